"""``rdm config deploy``: the shipped systemd unit and udev rules. The unit is read with the
standard library's configparser (systemd's INI form); the rules are checked token by token
against udev's ``KEY[{attr}]OP"value"`` grammar (udev(7)); both must agree with the shipped
onboard configuration's port names."""

from __future__ import annotations

import configparser
import re
import shlex

from rdm.cli import main
from rdm.commands.config import DEPLOY_FILES
from rdm.nodes.onboard_config_file import EXAMPLE_FILE

#: One udev token: KEY, optional {attribute}, an operator, a double-quoted value.
UDEV_TOKEN = re.compile(r'^([A-Z]+)(\{[A-Za-z_]+\})?(==|!=|\+=|=|:=)"([^"]*)"$')
MATCH_KEYS = {"SUBSYSTEM", "KERNEL", "ACTION", "ATTRS", "DRIVERS"}
ASSIGN_KEYS = {"SYMLINK", "GROUP", "MODE", "ATTR"}


def test_deploy_writes_the_files_and_never_overwrites(tmp_path, capsys) -> None:
    out = tmp_path / "deploy"
    assert main(["config", "deploy", str(out)]) == 0
    assert sorted(p.name for p in out.iterdir()) == sorted(DEPLOY_FILES)
    before = (out / "rdm-onboard.service").read_bytes()
    (out / "60-rdm-serial.rules").write_text("mine\n")
    capsys.readouterr()
    assert main(["config", "deploy", str(out)]) == 2
    assert "exists; not overwritten" in capsys.readouterr().err
    assert (out / "60-rdm-serial.rules").read_text() == "mine\n"
    assert (out / "rdm-onboard.service").read_bytes() == before


def test_the_unit_runs_the_onboard_node_on_a_config_file(tmp_path) -> None:
    assert main(["config", "deploy", str(tmp_path)]) == 0
    unit = configparser.ConfigParser(strict=True, interpolation=None)
    unit.optionxform = str  # systemd keys are case-sensitive
    unit.read(tmp_path / "rdm-onboard.service")
    assert set(unit.sections()) == {"Unit", "Service", "Install"}
    argv = shlex.split(unit["Service"]["ExecStart"])
    assert argv[0].endswith("/rdm") and argv[1:3] == ["onboard", "--config"]
    assert unit["Service"]["Restart"] == "on-failure"
    assert unit["Install"]["WantedBy"] == "multi-user.target"


def test_the_udev_rules_parse_and_name_the_configured_ports(tmp_path) -> None:
    assert main(["config", "deploy", str(tmp_path)]) == 0
    links = set()
    rules = 0
    for line in (tmp_path / "60-rdm-serial.rules").read_text().splitlines():
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        rules += 1
        tokens = [t.strip() for t in line.split(",")]
        parsed = [UDEV_TOKEN.match(t) for t in tokens]
        assert all(parsed), line
        for m in parsed:
            key, op, value = m.group(1), m.group(3), m.group(4)
            if op in ("==", "!="):
                assert key in MATCH_KEYS, line
            else:
                assert key in ASSIGN_KEYS, line
            if key == "SYMLINK":
                links.add(f"/dev/{value}")
    assert rules == 3
    # the example configuration's [ports] open exactly these names
    ports = re.findall(r"serial:(/dev/[A-Za-z_]+)@", EXAMPLE_FILE.read_text())
    assert set(ports) == links == {"/dev/flight_controller", "/dev/leptrino"}
