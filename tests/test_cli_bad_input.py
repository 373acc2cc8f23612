"""Bad input on the command line, as a careless user or an attacker gives it: every case is
the installed ``rdm`` run as a subprocess and must end in a message that names the option or
file and the rule broken, a non-zero exit and no traceback; nothing is written outside the
place the user named, and every JSON output is valid JSON (no NaN or Infinity token)."""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import threading
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

import rdm
from rdm.commands.output import OutputPathError, check_output_path
from rdm.output_files import OutputFileError, open_output, write_atomic

ENV = dict(os.environ, PYTHONPATH=str(Path(rdm.__file__).resolve().parent.parent))
Z9 = ",".join(["0"] * 9)  # the nine joints after the first of the shipped robot (10 joints)
#: Lines of a candump -L log: four Neuron enumeration frames of a run, then two bad lines.
CANDUMP = (
    "(0.100000) rdm-sim 70F# R\n"
    "(0.101000) rdm-sim 701# R\n"
    "(0.101000) rdm-sim 702# R\n"
    "garbage line\n"
    "(0.102000) can0 123#zz\n"
)


def rdm_cmd(*args: str, cwd: Path | None = None, timeout: float = 300):
    """``rdm ARGS`` in a fresh interpreter (the package under test), output captured."""
    return subprocess.run(
        [sys.executable, "-m", "rdm.cli", *args],
        capture_output=True,
        text=True,
        env=ENV,
        cwd=cwd,
        timeout=timeout,
    )


def refused(out: subprocess.CompletedProcess, code: int, *needles: str) -> None:
    """Exit ``code``, every needle in stderr, no traceback."""
    assert out.returncode == code, (out.returncode, out.stderr)
    for needle in needles:
        assert needle in out.stderr, (needle, out.stderr)
    assert "Traceback" not in out.stderr, out.stderr


def strict_json(text: str):
    """``json.loads`` that fails on the NaN/Infinity tokens Python's json would accept."""

    def no_constant(token: str) -> None:
        raise AssertionError(f"{token} in the JSON output")

    return json.loads(text, parse_constant=no_constant)


def urdf_limits(joint: str) -> tuple[float, float]:
    """(lower, upper) of a joint of the shipped rdm URDF, read with ElementTree."""
    urdf = Path(rdm.__file__).parent / "data" / "robots" / "rdm" / "rdm.urdf"
    for j in ET.parse(urdf).getroot().iter("joint"):
        if j.get("name") == joint:
            limit = j.find("limit")
            return float(limit.get("lower")), float(limit.get("upper"))
    raise KeyError(joint)


# ------------------------------------------------------------------ argument and path refusals


@pytest.mark.parametrize(
    ("args", "needles"),
    [
        (["plan", "--target", "0.1,0,0.3", "--out", "/proc/x.csv"], ["--out", "/proc/x.csv"]),
        (["plan", "--target", "0.1,0,0.3", "--plot", "/proc/x.png"], ["--plot", "/proc/x.png"]),
        (["plant", "--export", "/proc/x.xml"], ["--export", "/proc/x.xml"]),
        (["plant", "--export", "missing/x.xml"], ["--export", "'missing' does not exist"]),
        (["bench", "--quick", "--json", "/proc/x.json"], ["--json", "/proc/x.json"]),
        (["design", "--resolution", "nan"], ["--resolution", "'nan' must be finite and > 0"]),
        (["design", "--workers", "0"], ["--workers", "'0' must be >= 1"]),
        (["sim", "--speed", "inf"], ["--speed", "'inf' must be finite and > 0"]),
        (["sim", "--speed", "nan"], ["--speed", "'nan' must be finite and > 0"]),
        (["plant", "--ceiling-height", "nan"], ["--ceiling-height", "must be finite"]),
        (["model", "--q", "0,nan," + Z9[2:]], ["--q", "value [1] 'nan' is not finite"]),
        (["model", "--q", "0,x"], ["--q", "value [1] 'x' is not a number"]),
    ],
)
def test_bad_arguments_are_refused_while_parsing(args, needles, tmp_path):
    """Exit 2 from argparse before any work: /proc takes no new files (checked by creating
    one), a non-finite number is refused; a bench run would print its report on stdout."""
    out = rdm_cmd(*args, cwd=tmp_path, timeout=120)
    refused(out, 2, *needles)
    assert out.stdout == ""  # nothing ran: no report, no plan, no model
    assert list(tmp_path.iterdir()) == []  # no run folder, no partial file


def test_output_path_check_refuses_links_folders_and_devices(tmp_path):
    victim = tmp_path / "victim.txt"
    victim.write_text("keep")
    (tmp_path / "link.csv").symlink_to(victim)
    cases = {
        tmp_path / "link.csv": "symbolic link",
        tmp_path: "a folder",
        Path("/dev/null"): "not a regular file",
        tmp_path / "missing" / "x.csv": "does not exist",
        Path("/proc/x.csv"): "does not take new files",
    }
    for path, rule in cases.items():
        with pytest.raises(OutputPathError, match=rule) as exc:
            check_output_path(path, "--out")
        assert str(exc.value).startswith(f"--out {str(path)!r}")
    assert check_output_path(tmp_path / "new.csv", "--out") == tmp_path / "new.csv"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["link.csv", "victim.txt"]  # no probe
    # the command: refused, the link's target untouched
    out = rdm_cmd("plan", "--target", "0.2,-0.3,-0.7", "--out", str(tmp_path / "link.csv"))
    refused(out, 2, "--out", "symbolic link")
    assert victim.read_text() == "keep"


def test_output_files_never_write_through_a_link_or_into_a_fifo(tmp_path):
    victim = tmp_path / "victim"
    victim.write_bytes(b"keep")
    link = tmp_path / "can.log"
    link.symlink_to(victim)
    with pytest.raises(OutputFileError, match="symbolic link"):
        open_output(link, "w")
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    with pytest.raises(OutputFileError, match="not a regular file"):  # refused, not blocked
        open_output(fifo, "wb")
    write_atomic(link, "new\n")  # replaces the link itself
    assert victim.read_bytes() == b"keep"
    assert not link.is_symlink() and link.read_text() == "new\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["can.log", "fifo", "victim"]


def _writers():
    """(name, file it writes in a run folder, open-and-write) of every run-folder writer."""
    from rdm.link.capture_index import TimedCaptureFile
    from rdm.link.tapped_link import TappedLink
    from rdm.sim.candump import CandumpCapture
    from rdm.sim.mcap_log import McapLogger
    from rdm.sim.plots import plot_panels

    return [
        ("candump", "can.log", lambda p: CandumpCapture(p).close()),
        ("mcap", "signals.mcap", lambda p: McapLogger(p).finish()),
        ("capture", "uart/spinal.device_tx.bin", lambda p: TimedCaptureFile(p, float).close()),
        ("index", "uart/spinal.device_tx.bin.idx", lambda p: TimedCaptureFile(p[:-4], float)),
        ("tap", "uart/plain.bin", lambda p: TappedLink(None, tx_path=p)),
        (
            "plot",
            "plots/hover.png",
            lambda p: plot_panels(p, [0.0, 1.0], [("a", {"x": [0, 1]}, "m")]),
        ),
    ]


@pytest.mark.parametrize("writer", range(6), ids=[w[0] for w in _writers()])
def test_run_folder_writers_refuse_a_planted_link(writer, tmp_path):
    """A link planted in a run folder (by a racing process) is refused by every writer, its
    target untouched; summary.json and metrics.txt replace a link (write_atomic, above)."""
    from rdm.sim.run_folder import RunFolder

    _, rel, write = _writers()[writer]
    folder = RunFolder.create("hover", base=tmp_path / "runs", seed=0)
    victim = tmp_path / "victim"
    victim.write_bytes(b"keep")
    (folder.root / rel).symlink_to(victim)
    with pytest.raises(OutputFileError, match="symbolic link"):
        write(str(folder.root / rel))
    assert victim.read_bytes() == b"keep"


def test_summary_replaces_a_planted_link_atomically(tmp_path):
    from rdm.sim.metrics import Metric, write_summary

    victim = tmp_path / "victim"
    victim.write_bytes(b"keep")
    summary = tmp_path / "summary.json"
    summary.symlink_to(victim)
    write_summary(summary, [Metric("x", math.nan, 1.0, "m")], wall_s=math.inf)
    assert victim.read_bytes() == b"keep" and not summary.is_symlink()
    doc = strict_json(summary.read_text())
    assert doc["wall_s"] is None and doc["metrics"][0]["ours"] is None
    assert sorted(p.name for p in tmp_path.iterdir()) == ["summary.json", "victim"]


# ------------------------------------------------------------------------------ rdm decode


@pytest.mark.parametrize(
    "args",
    [["x.candump"], ["--format", "candump", "x.bin"], ["--json", "x.candump"]],
)
def test_decode_reads_every_candump_suffix_and_format_as_a_log(args, tmp_path):
    for name in ("x.log", "x.candump", "x.bin"):
        (tmp_path / name).write_text(CANDUMP)
    json_flag = ["--json"] if "--json" in args else []
    as_log = rdm_cmd("decode", *json_flag, "x.log", cwd=tmp_path)  # the .log of the same lines
    out = rdm_cmd("decode", *args, cwd=tmp_path)
    refused(out, 0, "candump: 3 records decoded, 2 bad {'syntax': 2}")
    assert out.stdout == as_log.stdout and out.stdout.count("\n") == 5
    assert "None" not in out.stderr  # the summary names the reason
    if "--json" in args:
        records = [strict_json(line) for line in out.stdout.splitlines()]
        kinds = [r["kind"] for r in records]
        assert kinds == ["enum_request", "enum_response", "enum_response", None, None]


@pytest.mark.parametrize(
    ("args", "needles"),
    [
        (["x.bin", "--layout", "missing.json"], ["--layout", "missing.json", "No such file"]),
        (["x.bin", "--layout", "bad.json"], ["--layout", "bad.json", "not JSON"]),
        (["x.bin", "--layout", "shape.json"], ["--layout", "subscribers"]),
        (["/nonexistent/x"], ["no such file: /nonexistent/x"]),
    ],
)
def test_decode_refuses_missing_files_and_bad_layouts(args, needles, tmp_path):
    (tmp_path / "x.bin").write_bytes(b"\xff\xfe\x00\x00")
    (tmp_path / "bad.json").write_text("{not json")
    (tmp_path / "shape.json").write_text('{"subscribers": 3, "publishers": []}')
    out = rdm_cmd("decode", *args, cwd=tmp_path)
    refused(out, 2, *needles)
    assert "cannot tell the format" not in out.stderr
    assert out.stdout == ""


@pytest.mark.parametrize("same", ["RUN/can.log", "RUN/../RUN/can.log", "alias.log"])
def test_decode_mcap_refuses_to_overwrite_its_input(same, tmp_path):
    run = tmp_path / "RUN"
    run.mkdir()
    (run / "can.log").write_text(CANDUMP)
    os.link(run / "can.log", tmp_path / "alias.log")  # the same file by another name
    out = rdm_cmd("decode", "RUN", "--mcap", same, cwd=tmp_path)
    refused(out, 2, f"--mcap {same!r} is the input", "can.log")
    assert (run / "can.log").read_text() == CANDUMP
    ok = rdm_cmd("decode", "RUN", "--mcap", "RUN/wire.mcap", cwd=tmp_path)
    refused(ok, 0)
    assert (run / "wire.mcap").read_bytes()[:8] == b"\x89MCAP0\r\n"


# ----------------------------------------------------------------------- rdm model, rdm plan


def test_model_non_finite_result_is_an_error_not_nan(tmp_path):
    lo, hi = urdf_limits("q1")
    for extra in ([], ["--json"]):
        out = rdm_cmd("model", "--q=1e308," + Z9, *extra)
        refused(out, 1, "not finite", "--q")
        assert f"joint q1 = 1e+308 rad is outside its limits [{lo:.6g}, {hi:.6g}]" in out.stderr
        assert out.stdout == ""  # neither NaN nor a margin of +inf


def test_model_negative_q_and_limit_warning(tmp_path):
    lo, hi = urdf_limits("q1")
    assert (lo, hi) == (pytest.approx(-math.pi / 2), pytest.approx(math.pi / 2))
    out = rdm_cmd("model", "--q", "-0.5,-0.25," + Z9[2:], "--json")
    refused(out, 0)
    report = strict_json(out.stdout)
    assert report["q"][:2] == [-0.5, -0.25]
    assert "warning" not in out.stderr
    out = rdm_cmd("model", "--q", "2.0," + Z9)  # 2.0 > pi/2
    refused(out, 0, "warning: --q[0]: joint q1 = 2 rad", f"[{lo:.6g}, {hi:.6g}]")
    assert "q2" not in out.stderr  # only the joint outside its limits


def test_plan_non_finite_result_unknown_robot_and_negative_target(tmp_path):
    out = rdm_cmd("plan", "--target", "1e308,0,0.3")
    refused(out, 1, "--target 1e308,0,0.3", "not finite")
    assert "Infinity" not in out.stdout and out.stdout == ""
    out = rdm_cmd("plan", "--robot", "nosuch", "--target", "0.2,0,-0.5")
    refused(out, 2, "unknown robot 'nosuch'", "'rdm' and 'rcm'", "TOML")
    assert "nosuch.urdf" not in out.stderr
    out = rdm_cmd("plan", "--target", "-0.2,0.3,-0.7")
    refused(out, 0)
    assert strict_json(out.stdout)["reached"] is True


def test_refused_neuron_board_leaves_no_bus_open():
    out = rdm_cmd("neuron", "--can", "virtual:rdm-bad-input", "--slave-id", "1", "99")
    refused(out, 2, "slave_id 99 not in 1..14")
    assert "not properly shut down" not in out.stderr


# --------------------------------------------------------------------------------- rdm sim


def _tree(root: Path) -> dict[str, bytes | str]:
    """Every entry under ``root``: file bytes, or a link's target."""
    out: dict[str, bytes | str] = {}
    for p in sorted(root.rglob("*")):
        key = str(p.relative_to(root))
        out[key] = (
            f"-> {os.readlink(p)}" if p.is_symlink() else (p.read_bytes() if p.is_file() else "dir")
        )
    return out


def test_sim_refuses_a_non_empty_run_folder_and_replace_follows_no_link(tmp_path):
    outside = tmp_path / "outside"
    outside.mkdir()
    (outside / "victim.log").write_text("not yours\n")
    (outside / "sub").mkdir()
    (outside / "sub" / "keep").write_text("keep\n")
    folder = tmp_path / "runs" / "hover-seed0"
    (folder / "plots").mkdir(parents=True)
    (folder / "old.txt").write_text("an older run\n")
    (folder / "can.log").symlink_to(outside / "victim.log")
    (folder / "plots" / "linked").symlink_to(outside / "sub")
    before = _tree(outside)
    out = rdm_cmd("sim", "hover", "--duration", "0.2", "--out", str(tmp_path / "runs"))
    refused(out, 2, str(folder), "not empty", "--replace")
    assert (folder / "old.txt").read_text() == "an older run\n"
    assert _tree(outside) == before
    out = rdm_cmd(
        "sim", "hover", "--duration", "0.2", "--out", str(tmp_path / "runs"), "--replace", "--json"
    )
    assert out.returncode in (0, 1), out.stderr  # 1: a 0.2 s hover fails its height metric
    assert "Traceback" not in out.stderr
    summary = strict_json(out.stdout)
    assert summary["simulated_s"] == pytest.approx(0.2)
    assert _tree(outside) == before  # the link was removed, its target never written
    names = {p.name for p in folder.iterdir()}
    assert "old.txt" not in names and "INCOMPLETE" not in names
    assert {"can.log", "summary.json", "metrics.txt", "signals.mcap"} <= names
    assert not (folder / "can.log").is_symlink() and (folder / "can.log").stat().st_size > 0
    assert strict_json((folder / "summary.json").read_text()) == summary
    assert not any(p.is_symlink() for p in folder.rglob("*"))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["outside", "runs"]


def test_sim_refuses_a_run_folder_that_is_a_link(tmp_path):
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (tmp_path / "runs").mkdir()
    (tmp_path / "runs" / "hover-seed0").symlink_to(elsewhere)
    out = rdm_cmd("sim", "hover", "--duration", "0.2", "--out", str(tmp_path / "runs"))
    refused(out, 2, "symbolic link")
    assert list(elsewhere.iterdir()) == []


@pytest.mark.parametrize("when", ["building", "running"])
def test_sim_ctrl_c_exits_130_and_marks_the_run_incomplete(when, tmp_path):
    """Ctrl-C while the stack is being built (its signal log just made) or while it runs
    (a simulated second done): exit 130, one line, no traceback, no bus left open, the run
    folder marked INCOMPLETE with the reason."""
    folder = tmp_path / "hover-seed0"
    cmd = [sys.executable, "-m", "rdm.cli", "sim", "hover", "--duration", "600"]
    proc = subprocess.Popen(
        [*cmd, "--out", str(tmp_path)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        env=ENV,
        start_new_session=True,  # its own process group: SIGINT to it as a terminal's Ctrl-C
    )
    chunks: list[bytes] = []
    reader = threading.Thread(
        target=lambda: chunks.extend(iter(lambda: proc.stderr.read1(4096), b"")), daemon=True
    )
    reader.start()
    if when == "building":
        started = (folder / "signals.mcap").exists
    else:
        started = lambda: b"1.0 / 600 s simulated" in b"".join(chunks)  # noqa: E731
    try:
        deadline = time.monotonic() + 240
        while not started() and proc.poll() is None:
            assert time.monotonic() < deadline, b"".join(chunks).decode()
            time.sleep(0.002)
        os.killpg(proc.pid, signal.SIGINT)  # the command and its plot worker, as Ctrl-C does
        proc.wait(timeout=240)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    reader.join(timeout=60)
    err = b"".join(chunks).decode()
    assert proc.returncode == 130, err
    assert "Traceback" not in err and "KeyboardInterrupt" not in err, err
    assert err.rstrip().splitlines()[-1] == (
        f"rdm sim: interrupted by Ctrl-C (SIGINT); {folder} marked INCOMPLETE"
    ), err
    assert "interrupted by Ctrl-C" in (folder / "INCOMPLETE").read_text()
    assert not (folder / "summary.json").exists()
