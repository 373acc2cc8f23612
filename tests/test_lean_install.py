"""The base install (``pip install .``, no extra) carries the robot's computer: the onboard
node, the ground link and their configuration files; the simulator, logs and plots are the
``sim`` extra, and a command that needs a missing extra says which one in one line.

Two levels:

* fast, in this environment: the extras of ``pyproject.toml`` (read with tomllib), and the
  commands run in a subprocess where an import hook refuses every module of the ``sim`` and
  ``bench`` extras as a missing package would (``ModuleNotFoundError`` with its name);
* slow (``-m slow``): the wheel built once (``pip wheel . --no-deps``), installed without
  the extra into a fresh virtual environment (its dependencies from the package index), and
  ``rdm onboard`` from that environment serving a scripted Spinal on a pty.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import textwrap
import zipfile
from pathlib import Path

import pytest
from spinal_peer import drive_spinal, read_line

from rdm.cli import OPTIONAL_MODULES, missing_extra
from rdm.commands.onboard_record import OPTIONAL_PROBES

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

ROOT = Path(__file__).resolve().parents[1]
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())
#: What the onboard node and the ground link import (hand-listed: the issue's lean set).
BASE = {"numpy", "pyserial", "python-can", "ruckig", "tomli"}
#: The simulator's modules, none of which the onboard stack may need.
SIM_MODULES = ("mujoco", "matplotlib", "scipy", "mcap", "msgpack")
PIP = (sys.executable, "-m", "pip", "--quiet", "--disable-pip-version-check")


def _name(requirement: str) -> str:
    """The distribution name of a PEP 508 requirement string, normalised (PEP 503)."""
    match = re.match(r"\s*([A-Za-z0-9][A-Za-z0-9._-]*)", requirement)
    assert match, requirement
    return re.sub(r"[-_.]+", "-", match.group(1)).lower()


def _extra(name: str) -> set[str]:
    return {_name(r) for r in PYPROJECT["project"]["optional-dependencies"][name]}


# -- pyproject.toml -------------------------------------------------------------------------


def test_base_dependencies_are_the_onboard_set() -> None:
    """A simulator package slipping back into ``dependencies`` fails here."""
    assert {_name(r) for r in PYPROJECT["project"]["dependencies"]} == BASE


def test_test_extra_contains_the_sim_extra() -> None:
    """The suite runs the simulator: ``test`` must carry every ``sim`` package."""
    missing = _extra("sim") - _extra("test")
    assert not missing, f"add {sorted(missing)} to the test extra"


def test_every_optional_module_is_in_the_extra_it_names() -> None:
    """The dispatcher's message tells the user to install an extra: that extra must hold the
    package (module and distribution names coincide for these)."""
    for module, (extra, _what) in OPTIONAL_MODULES.items():
        assert module in _extra(extra), f"{module} -> rdm[{extra}], which does not list it"
    assert set(SIM_MODULES) <= {m for m, (e, _) in OPTIONAL_MODULES.items() if e == "sim"}


# -- the dispatcher ---------------------------------------------------------------------------


def test_missing_extra_line_names_extra_and_module() -> None:
    line = missing_extra("sim", ModuleNotFoundError("No module named 'scipy'", name="scipy.sparse"))
    assert line is not None and line.startswith("rdm sim: needs the simulator extra (scipy ")
    assert 'pip install "rdm[sim]"' in line and "\n" not in line
    # a module of no extra is a real error, not an install hint
    assert missing_extra("sim", ModuleNotFoundError("x", name="rdm.nodes.nothing")) is None
    assert missing_extra("sim", ModuleNotFoundError("x")) is None


def test_dispatch_reraises_a_missing_module_of_no_extra(monkeypatch, capsys) -> None:
    """Only the extras' modules become a one-line hint; any other missing module is a bug
    and keeps its traceback."""
    import rdm.cli as cli

    def fail(name: str) -> None:
        raise ModuleNotFoundError(f"No module named {name!r}", name="rdm.commands.gone")

    monkeypatch.setattr(cli.importlib, "import_module", fail)
    with pytest.raises(ModuleNotFoundError):
        cli.main(["model"])

    def fail_mujoco(name: str) -> None:
        raise ModuleNotFoundError("No module named 'mujoco'", name="mujoco")

    monkeypatch.setattr(cli.importlib, "import_module", fail_mujoco)
    assert cli.main(["plant"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("rdm plant: needs the simulator extra (mujoco is not installed)")


# -- the commands with the extras' modules refused -------------------------------------------

#: Prepended to each subprocess script: every module of the extras is missing; the names
#: asked for are written to stderr at exit as ``ASKED <json list>``.
_BLOCK = textwrap.dedent(
    """
    import atexit, json, sys
    BLOCKED = {blocked!r}
    ASKED = []
    class Missing:
        def find_spec(self, name, path=None, target=None):
            if name.split(".")[0] in BLOCKED:
                ASKED.append(name)
                raise ModuleNotFoundError(f"No module named {{name!r}}", name=name)
            return None
    sys.meta_path.insert(0, Missing())
    atexit.register(lambda: print("ASKED " + json.dumps(ASKED), file=sys.stderr))
    from rdm.cli import main
    """
).format(blocked=sorted(OPTIONAL_MODULES))


def _run_blocked(script: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-c", _BLOCK + textwrap.dedent(script)],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=cwd,
    )


def _asked(stderr: str) -> list[str]:
    (line,) = [x for x in stderr.splitlines() if x.startswith("ASKED ")]
    return json.loads(line[len("ASKED ") :])


def test_onboard_ctl_and_config_need_no_extra(tmp_path) -> None:
    """``rdm onboard`` with the ground link, ``rdm ctl`` (keygen and a signed status
    round-trip), ``rdm config check``, ``rdm onboard --help`` and an end-effector plan run
    to exit 0 and never ask for a module of an extra."""
    out = _run_blocked(
        """
        import os, signal, socket, threading, time
        from rdm.nodes.onboard_config_file import EXAMPLE_FILE
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.bind(("127.0.0.1", 0))
            port = s.getsockname()[1]
        codes = {"keygen": main(["ctl", "keygen", "robot.key"])}
        to = f"udp:127.0.0.1:{port}"
        def ctl():
            # until the node answers (its start-up takes a moment), then stop it as Ctrl-C does
            for _ in range(100):
                codes["status"] = main(["ctl", "--to", to, "--key", "robot.key", "--retries",
                                        "0", "--timeout", "0.3", "status"])
                if codes["status"] == 0:
                    break
            os.kill(os.getpid(), signal.SIGTERM)
        t = threading.Thread(target=ctl)
        t.start()
        codes["onboard"] = main(["onboard", "--uart", "loop://", "--control", to, "--key",
                                 "robot.key", "--duration", "60"])
        t.join()
        codes["config"] = main(["config", "check", str(EXAMPLE_FILE)])
        from rdm.ground.ee import EePlanner
        import numpy as np
        plan = EePlanner("rdm").submit([0.3, 0.0, 0.2], np.zeros(10)).result(timeout=60)
        codes["plan_columns"] = int(plan.zeta.shape[1])
        try:
            main(["onboard", "--help"])
        except SystemExit as e:
            codes["onboard_help"] = e.code
        print("CODES " + json.dumps(codes))
        """,
        tmp_path,
    )
    assert out.returncode == 0, out.stderr
    (line,) = [x for x in out.stdout.splitlines() if x.startswith("CODES ")]
    codes = json.loads(line[len("CODES ") :])
    assert codes["keygen"] == 0 and codes["status"] == 0 and codes["onboard"] == 0
    assert codes["config"] == 0, out.stderr
    assert codes["onboard_help"] == 0 and codes["plan_columns"] == 16  # zeta: 6 base + 10 joints
    # the flight recorder looks for mcap (and finds it refused): a probe, never an import
    assert set(_asked(out.stderr)) <= set(OPTIONAL_PROBES) == {"mcap"}


@pytest.mark.parametrize(
    ("argv", "module"),
    [
        (["sim", "--duration", "1"], None),
        (["hil", "--can", "udp", "--duration", "1"], None),
        (["plant"], "mujoco"),
        (["plan", "--target", "0.3,0,0.2,0,0,0.1"], "scipy"),
    ],
)
def test_simulator_commands_name_the_extra(tmp_path, argv, module) -> None:
    """Each command that needs the simulator ends with one line and exit 2 (no traceback)."""
    out = _run_blocked(f"sys.exit(main({argv!r}))", tmp_path)
    assert out.returncode == 2, out.stderr
    lines = [x for x in out.stderr.splitlines() if not x.startswith("ASKED ")]
    assert len(lines) == 1 and "Traceback" not in out.stderr, out.stderr
    assert lines[0].startswith(f"rdm {argv[0]}: needs the simulator extra (")
    assert lines[0].find('pip install "rdm[sim]"') > 0
    if module is not None:
        assert f"({module} is not installed)" in lines[0]


def test_spinal_mirror_needs_no_extra(tmp_path) -> None:
    """``rdm spinal`` (the firmware mirror on a UART and a CAN bus, a layer below the
    simulator) runs for its duration and stops with its diagnostics, never asking for a
    module of an extra."""
    out = _run_blocked(
        'sys.exit(main(["spinal", "--uart", "pty", "--can", "virtual:x", "--duration", "1"]))',
        tmp_path,
    )
    assert out.returncode == 0 and "Traceback" not in out.stderr, out.stderr
    (line,) = [x for x in out.stdout.splitlines() if x.startswith("rdm spinal: stopped ")]
    summary = json.loads(line[len("rdm spinal: stopped ") :])
    assert summary["realtime"]["ticks"] > 0
    assert _asked(out.stderr) == []


#: Modules only the ``test`` and ``bench`` extras install.
TEST_ONLY = ["cantools", "clarabel", "hypothesis", "osqp", "pytest", "rosbags", "ruff"]


def test_sim_needs_only_the_sim_extra(tmp_path) -> None:
    """``rdm sim`` (the README's quick start after ``pip install ".[sim]"``) runs with every
    module of the test and bench extras refused: the sim extra is all it needs."""
    script = _BLOCK.replace(repr(sorted(OPTIONAL_MODULES)), repr(TEST_ONLY), 1)
    assert script != _BLOCK
    out = subprocess.run(
        [
            sys.executable,
            "-c",
            script + "sys.exit(main(['sim', 'hover', '--duration', '1', '--out', 'run']))",
        ],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=tmp_path,
    )
    # 1 s is too short for the hover's pass criteria: exit 1 (failed evaluation), not 2
    assert out.returncode in (0, 1) and "Traceback" not in out.stderr, out.stderr
    assert _asked(out.stderr) == []
    assert json.loads((tmp_path / "run" / "hover-seed0" / "summary.json").read_text())


# -- the built wheel in a fresh virtual environment (slow) ------------------------------------


@pytest.fixture(scope="module")
def lean_venv(tmp_path_factory) -> dict[str, Path]:
    """The wheel of this tree (built once) installed without extras in a fresh venv."""
    wheels = tmp_path_factory.mktemp("wheel")
    subprocess.run(
        [*PIP, "wheel", str(ROOT), "--no-deps", "-w", str(wheels)],
        check=True,
        timeout=1800,
    )
    (wheel,) = wheels.glob("rdm-*.whl")
    venv = tmp_path_factory.mktemp("venv")
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, timeout=300)
    python = venv / "bin" / "python"
    subprocess.run(
        [str(python), *PIP[1:], "install", str(wheel)],
        check=True,
        timeout=900,
    )
    return {"wheel": wheel, "venv": venv, "python": python, "rdm": venv / "bin" / "rdm"}


def _venv_env() -> dict[str, str]:
    """This process's environment without anything that would reach this tree's package."""
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}
    env["PYTHONUNBUFFERED"] = "1"
    return env


@pytest.mark.slow
@pytest.mark.timeout(2400)
def test_wheel_requires_only_the_base(lean_venv) -> None:
    """The wheel's metadata: unconditional requirements are the base set; the simulator's
    packages only under ``extra == 'sim'``."""
    with zipfile.ZipFile(lean_venv["wheel"]) as z:
        (meta,) = [n for n in z.namelist() if n.endswith(".dist-info/METADATA")]
        lines = z.read(meta).decode().splitlines()
    requires = [x.split(":", 1)[1].strip() for x in lines if x.startswith("Requires-Dist:")]
    assert {_name(r) for r in requires if "extra ==" not in r} == BASE
    sim = {_name(r) for r in requires if re.search(r"extra\s*==\s*['\"]sim['\"]", r)}
    assert set(SIM_MODULES) <= sim


@pytest.mark.slow
@pytest.mark.timeout(2400)
def test_lean_venv_has_the_package_and_no_simulator(lean_venv, tmp_path) -> None:
    out = subprocess.run(
        [
            str(lean_venv["python"]),
            "-c",
            "import importlib.util, json, rdm; print(json.dumps({'rdm': rdm.__file__, "
            f"'found': [m for m in {list(SIM_MODULES)!r} if importlib.util.find_spec(m)]}}))",
        ],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=tmp_path,
        env=_venv_env(),
    )
    assert out.returncode == 0, out.stderr
    found = json.loads(out.stdout)
    assert Path(found["rdm"]).is_relative_to(lean_venv["venv"])  # the wheel, not this tree
    assert found["found"] == []
    mujoco = subprocess.run(
        [str(lean_venv["python"]), "-c", "import mujoco"],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=tmp_path,
        env=_venv_env(),
    )
    assert mujoco.returncode == 1 and "ModuleNotFoundError" in mujoco.stderr


@pytest.mark.slow
@pytest.mark.timeout(2400)
def test_lean_onboard_node_serves_a_spinal_peer(lean_venv, tmp_path) -> None:
    """``rdm onboard`` from the lean venv: the rosserial handshake with a scripted Spinal on
    its pty, ``uav_info`` and ``motor_info`` published (the Hydrus example's values, from
    the fact sheet's MotorInfo.yaml, compared as the float32 the wire carries), ARM_ON
    acked, and exit 0 at the end of ``--duration``."""
    import numpy as np

    # ASSUMPTION: 4 s cover handshake and arming on a loaded CI machine (0.2 s on an idle
    # one); the node stops on its own at the end of them.
    onboard_args = ("--uart", "pty", "--foot-sensor", "none", "--arm", "--duration", "4")
    proc = subprocess.Popen(
        [str(lean_venv["rdm"]), "onboard", *onboard_args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=tmp_path,
        env=_venv_env(),
    )
    try:
        uart_path = read_line(proc, "rdm onboard: uart pty").split()[-1]
        read_line(proc, "rdm onboard: ready")
        spinal, got = drive_spinal(uart_path, 30.0, done=lambda _: proc.poll() is not None)
        out, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 0, err
    assert spinal.configured
    uav = got["uav_info"][0]
    assert (uav.motor_num, uav.uav_model) == (4, 16)  # 4 rotors, HYDRUS
    pwm = got["motor_info"][0]
    f32 = np.float32
    assert (pwm.min_pwm, pwm.max_pwm) == (f32(0.59), f32(0.9375))
    assert (pwm.min_thrust, pwm.force_landing_thrust, pwm.pwm_conversion_mode) == (1.0, 6.5, 0)
    (unit,) = pwm.motor_info
    assert (unit.voltage, unit.max_thrust) == (f32(25.2), 20.0)
    assert list(unit.polynominal) == [f32(12.3593793002), f32(-6.627443098), f32(0.07983707), 0, 0]
    assert 0 in [m.cmd for m in got.get("flight_config_cmd", [])], out  # ARM_ON_CMD = 0
    final = json.loads(out.strip().splitlines()[-1])
    # acked; without motion capture the node then lands (mocap_loss_force_landing_s)
    assert final["counts"]["rx:flight_config_ack"] >= 1 and final["ticks"] >= 120
    assert final["session"].get("sync_lost", 0) == 0  # one handshake, kept


@pytest.mark.slow
@pytest.mark.timeout(2400)
def test_lean_commands(lean_venv, tmp_path) -> None:
    """From the lean venv: ``rdm config check`` of the shipped example (a data file of the
    wheel) gives its JSON; ``rdm sim`` and ``rdm hil --can udp`` name the extra."""
    check = subprocess.run(
        [str(lean_venv["rdm"]), "config", "check", "--robot", "rdm", "/dev/null"],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=tmp_path,
        env=_venv_env(),
    )
    assert check.returncode == 0, check.stderr  # an empty file: every default
    example = subprocess.run(
        [str(lean_venv["rdm"]), "config", "example"],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=tmp_path,
        env=_venv_env(),
    )
    assert example.returncode == 0 and tomllib.loads(example.stdout)["rate_hz"] == 40.0
    (tmp_path / "robot.toml").write_text(example.stdout)
    resolved = subprocess.run(
        [str(lean_venv["rdm"]), "config", "check", "robot.toml"],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=tmp_path,
        env=_venv_env(),
    )
    assert resolved.returncode == 0, resolved.stderr
    # the example sets one value beside the defaults: the damped roll loop's LQI weights
    # (docs/flying.md "The hover's roll loop"), written out here as the file carries them
    example_config = json.loads(resolved.stdout)["config"]
    default_config = json.loads(check.stdout)["config"]
    assert example_config.pop("lqi_q_weights") == [
        20.0, 30.0, 30.0, 1.0, 600.0, 80.0, 100.0, 50.0, 20.0, 0.15, 1.0, 0.5
    ]  # fmt: skip
    assert default_config.pop("lqi_q_weights") is None
    assert example_config == default_config
    for argv in (["sim"], ["hil", "--can", "udp", "--duration", "1"]):
        out = subprocess.run(
            [str(lean_venv["rdm"]), *argv],
            capture_output=True,
            text=True,
            timeout=120,
            cwd=tmp_path,
            env=_venv_env(),
        )
        assert out.returncode == 2 and "Traceback" not in out.stderr, out.stderr
        assert out.stderr.strip().endswith('pip install ".[sim]")'), out.stderr
        assert len(out.stderr.strip().splitlines()) == 1
