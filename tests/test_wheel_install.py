"""The distribution files: ``scripts/build_wheels.sh`` builds a manylinux abi3 wheel and an sdist;
the wheel, installed without extras into a fresh virtual environment (its dependencies from the
package index), runs ``rdm onboard`` against the Spinal mirror (``rdm spinal``) on a pty.

Oracles, none of them this package's code: the wheel's ``WHEEL`` file read with the standard
library's email parser and its file name with ``packaging``; ``auditwheel show`` (the PyPA's
audit of the ELF's linked libraries and symbol versions); ``git ls-files`` for what the sdist
must carry; ``pip list`` of the venv and the interpreter's ``-X importtime`` trace for what was
installed and imported; the two processes' counts of the same bytes on the pty.

Slow: one release build (cargo reuses the build of ``pip install .`` when it shares the
target folder: about a minute) and one venv install.
"""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import tarfile
import zipfile
from email.parser import HeaderParser
from pathlib import Path

import pytest
from packaging.tags import Tag
from packaging.utils import parse_wheel_filename
from spinal_peer import read_line

ROOT = Path(__file__).resolve().parents[1]
#: Packages of the ``sim`` extra that the onboard stack must neither install nor import.
SIMULATOR = ("mujoco", "matplotlib", "scipy", "mcap")
PIP = ("-m", "pip", "--quiet", "--disable-pip-version-check")


def _env() -> dict[str, str]:
    """This process's environment without anything that would reach this tree's package."""
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}
    env["PYTHONUNBUFFERED"] = "1"
    return env


@pytest.fixture(scope="module")
def dist(tmp_path_factory) -> dict[str, Path]:
    """``scripts/build_wheels.sh`` run into a temporary folder: the wheel, the sdist and the
    script's output (which ends with ``auditwheel show``)."""
    out = tmp_path_factory.mktemp("dist")
    env = {**os.environ, "RDM_DIST": str(out), "PYTHON": sys.executable}
    run = subprocess.run(
        ["bash", str(ROOT / "scripts" / "build_wheels.sh")],
        capture_output=True,
        text=True,
        timeout=1800,
        env=env,
    )
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-3000:]
    (wheel,) = out.glob("rdm-*.whl")
    (sdist,) = out.glob("rdm-*.tar.gz")
    return {"wheel": wheel, "sdist": sdist, "log": run.stdout}


@pytest.fixture(scope="module")
def venv(dist, tmp_path_factory) -> Path:
    """A fresh venv (no system site-packages) with the wheel installed without extras."""
    root = tmp_path_factory.mktemp("venv")
    subprocess.run([sys.executable, "-m", "venv", str(root)], check=True, timeout=300)
    python = root / "bin" / "python"
    subprocess.run([str(python), *PIP, "install", str(dist["wheel"])], check=True, timeout=900)
    return root


#: PEP 599's legacy alias and its PEP 600 glibc version.
LEGACY = {"manylinux2014_x86_64": "manylinux_2_17_x86_64"}


def _manylinux(tag: str) -> tuple[int, int]:
    """``manylinux_2_17_x86_64`` (or ``manylinux2014_x86_64``) -> (2, 17); AssertionError for
    any other platform tag."""
    match = re.fullmatch(r"manylinux_(\d+)_(\d+)_x86_64", LEGACY.get(tag, tag))
    assert match, f"not a manylinux x86_64 platform tag: {tag}"
    return int(match.group(1)), int(match.group(2))


@pytest.mark.slow
@pytest.mark.timeout(2400)
def test_wheel_is_manylinux_abi3(dist) -> None:
    """The ``WHEEL`` file's tags and the file name agree: CPython >= 3.10 stable ABI, manylinux
    x86_64, not pure Python; the only native file is the extension module."""
    with zipfile.ZipFile(dist["wheel"]) as z:
        (name,) = [n for n in z.namelist() if n.endswith(".dist-info/WHEEL")]
        wheel_file = HeaderParser().parsestr(z.read(name).decode())
        native = [n for n in z.namelist() if n.endswith(".so") or ".so." in n]
    assert wheel_file["Root-Is-Purelib"].strip().lower() == "false"
    tags = {Tag(*t.strip().split("-")) for t in wheel_file.get_all("Tag")}
    _dist_name, _version, _build, name_tags = parse_wheel_filename(dist["wheel"].name)
    assert tags == set(name_tags)
    for tag in tags:
        assert (tag.interpreter, tag.abi) == ("cp310", "abi3"), tag
        assert _manylinux(tag.platform) == (2, 17)  # the script's policy: glibc >= 2.17
    assert native == ["rdm/_rdm.abi3.so"]


@pytest.mark.slow
@pytest.mark.timeout(2400)
def test_auditwheel_agrees_with_the_tag(dist) -> None:
    """``auditwheel show``: the wheel is consistent with the manylinux tag it carries (the
    lowest policy its symbol versions allow is at most the tag's) and needs no library
    outside that policy's list."""
    show = subprocess.run(
        [sys.executable, "-m", "auditwheel", "show", str(dist["wheel"])],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert show.returncode == 0, show.stderr
    text = " ".join(show.stdout.split())  # auditwheel wraps its sentences
    found = re.search(r'consistent with the following platform tag: "([^"]+)"', text)
    assert found, show.stdout
    (_name, _version, _build, tags) = parse_wheel_filename(dist["wheel"].name)
    carried = {_manylinux(t.platform) for t in tags}
    assert _manylinux(found.group(1)) <= min(carried), show.stdout
    assert "system-provided shared libraries" in text or "requires no external" in text
    assert "graft" not in text.lower(), show.stdout  # nothing to bundle (auditwheel repair)
    assert found.group(0) in " ".join(dist["log"].split())  # the script's own report


@pytest.mark.slow
@pytest.mark.timeout(2400)
def test_sdist_carries_every_build_input(dist) -> None:
    """Every tracked file the build reads (both crates, the workspace manifest and lock file,
    the Python package with its data and firmware_protocol definitions) is in the sdist."""
    tracked = subprocess.run(
        ["git", "ls-files", "crates/rdm_core/src", "crates/rdm_py/src", "python/rdm"],
        capture_output=True,
        text=True,
        check=True,
        cwd=ROOT,
    ).stdout.split()
    assert any(p.startswith("python/rdm/firmware_protocol/") for p in tracked)
    with tarfile.open(dist["sdist"]) as tar:
        names = {n.split("/", 1)[1] for n in tar.getnames() if "/" in n}
    needed = {"Cargo.toml", "Cargo.lock", "pyproject.toml", "crates/rdm_core/Cargo.toml"}
    needed |= {"crates/rdm_py/Cargo.toml", *tracked}
    missing = sorted(needed - names)
    assert not missing, missing[:20]
    assert not [n for n in names if n.endswith(".so")]  # no built extension of this tree


def _installed(venv: Path) -> set[str]:
    out = subprocess.run(
        [str(venv / "bin" / "python"), "-m", "pip", "list", "--format", "json"],
        capture_output=True,
        text=True,
        check=True,
        timeout=120,
        env=_env(),
    )
    return {re.sub(r"[-_.]+", "-", d["name"]).lower() for d in json.loads(out.stdout)}


@pytest.mark.slow
@pytest.mark.timeout(2400)
def test_fresh_venv_runs_onboard_against_the_spinal_mirror(venv, tmp_path) -> None:
    """From the venv: ``rdm spinal`` on a pty (a 4-rotor Spinal mirror, CAN on a virtual bus
    with no Neuron), ``rdm onboard --arm`` on the pty's other end for 4 s. Both processes
    count the same frames; the node's interpreter imports no simulator package, and none is
    installed."""
    installed = _installed(venv)
    assert {"rdm", "numpy", "pyserial", "python-can", "ruckig"} <= installed
    assert not installed & set(SIMULATOR), sorted(installed & set(SIMULATOR))
    where = subprocess.run(
        [str(venv / "bin" / "python"), "-c", "import rdm._rdm as m; print(m.__file__)"],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=tmp_path,
        env=_env(),
    )
    assert Path(where.stdout.strip()).is_relative_to(venv), where.stderr  # the wheel's module

    mirror = subprocess.Popen(
        [str(venv / "bin" / "rdm"), "spinal", "--uart", "pty", "--can", "virtual:wheel"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=tmp_path,
        env=_env(),
    )
    try:
        pty = read_line(mirror, "rdm spinal: ready uart=").split("uart=")[1].split()[0]
        # ASSUMPTION: 4 s cover handshake and arming on a loaded CI machine (0.5 s idle).
        onboard = subprocess.run(
            [
                str(venv / "bin" / "python"),
                "-X",
                "importtime",
                "-m",
                "rdm.cli",
                "onboard",
                "--uart",
                f"serial:{pty}",
                "--foot-sensor",
                "none",
                "--arm",
                "--duration",
                "4",
            ],
            capture_output=True,
            text=True,
            timeout=300,
            cwd=tmp_path,
            env=_env(),
        )
        mirror.send_signal(signal.SIGTERM)
        mirror_out, mirror_err = mirror.communicate(timeout=60)
    finally:
        if mirror.poll() is None:
            mirror.kill()
            mirror.communicate()
    assert onboard.returncode == 0, onboard.stderr[-3000:]
    assert mirror.returncode == 0, mirror_err

    imported = {
        line.split("|")[-1].strip()
        for line in onboard.stderr.splitlines()
        if line.startswith("import time:") and "|" in line
    }
    assert "rdm._rdm" in imported and "serial" in imported
    assert not {m for m in imported if m.split(".")[0] in SIMULATOR}

    status = json.loads(onboard.stdout.strip().splitlines()[-1])
    (line,) = [x for x in mirror_out.splitlines() if x.startswith("rdm spinal: stopped ")]
    spinal = json.loads(line[len("rdm spinal: stopped ") :])
    assert spinal["rosserial"]["configured"] and spinal["control"]["motor_number"] == 4
    for topic in ("uav_info", "motor_info", "flight_config_cmd"):
        assert status["published"][topic] >= 1
        assert spinal["received"][topic] == status["published"][topic], topic
    assert spinal["acks"].get("0", 0) >= 1  # ARM_ON_CMD acked by the mirror
    assert status["counts"]["rx:flight_config_ack"] >= 1
    assert 0 < status["counts"]["rx:imu"] <= spinal["published"]["imu"]
    assert status["session"].get("sync_lost", 0) == 0 and status["ticks"] >= 80
