"""``rdm onboard``'s real-time options: refused with one line when the OS denies them, reported
in the status when granted; the loop's figures and the late-tick tolerance in the status and
the configuration file."""

from __future__ import annotations

import ctypes
import json
import os
import resource
import subprocess
import sys

import pytest

#: Linux capability numbers (``<linux/capability.h>``) and ``PR_CAPBSET_DROP``.
CAP_IPC_LOCK, CAP_SYS_NICE, PR_CAPBSET_DROP = 14, 23, 24


def _unprivileged() -> None:
    """In the child before exec: no rtprio, a 64 KiB memlock limit, and (as root) neither
    CAP_SYS_NICE nor CAP_IPC_LOCK in the bounding set, so the exec'd program has neither."""
    resource.setrlimit(resource.RLIMIT_RTPRIO, (0, 0))
    resource.setrlimit(resource.RLIMIT_MEMLOCK, (65536, 65536))
    libc = ctypes.CDLL(None, use_errno=True)
    for cap in (CAP_IPC_LOCK, CAP_SYS_NICE):
        libc.prctl(PR_CAPBSET_DROP, cap, 0, 0, 0)  # fails harmlessly when not root


def onboard(*args: str, unprivileged: bool = False) -> subprocess.CompletedProcess:
    return subprocess.run(
        [
            sys.executable,
            "-m",
            "rdm.cli",
            "onboard",
            "--no-record",
            "--uart",
            "pty",
            "--duration",
            "0.3",
            *args,
        ],
        capture_output=True,
        text=True,
        timeout=120,
        preexec_fn=_unprivileged if unprivileged else None,
    )


def _refused(out: subprocess.CompletedProcess, start: str) -> str:
    assert out.returncode == 2, out.stderr
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in out.stderr, out.stderr
    assert lines[0].startswith(f"rdm onboard: {start}"), lines[0]
    return lines[0]


@pytest.mark.parametrize(
    ("args", "start", "says"),
    [
        (("--rt-priority", "50"), "--rt-priority 50: the OS refused SCHED_FIFO", "CAP_SYS_NICE"),
        (("--mlock",), "--mlock: the OS refused mlockall", "CAP_IPC_LOCK"),
    ],
)
def test_an_option_the_os_denies_is_refused_in_one_line(args, start, says) -> None:
    assert says in _refused(onboard(*args, unprivileged=True), start)


def test_a_cpu_outside_the_allowed_set_and_a_priority_out_of_range_are_refused() -> None:
    cpu = max(os.sched_getaffinity(0)) + 64
    _refused(onboard("--cpu", str(cpu)), f"--cpu {cpu}: the OS refused the CPU affinity")
    high = os.sched_get_priority_max(os.SCHED_FIFO)
    for bad in ("0", str(high + 1)):
        _refused(onboard("--rt-priority", bad), f"--rt-priority {bad}: must be an integer 1..")
    _refused(onboard("--late-tolerance", "-0.001"), "late_tolerance_s=-0.001 must be finite")


def test_granted_options_and_the_loop_figures_are_in_the_status() -> None:
    cpu = min(os.sched_getaffinity(0))
    out = onboard("--cpu", str(cpu), "--gc-freeze", "--late-tolerance", "0.003")
    assert out.returncode == 0, out.stderr
    status = json.loads(out.stdout.strip().splitlines()[-1])
    assert status["realtime"] == {
        "rt_priority": None,
        "cpus": [cpu],
        "mlock": False,
        "gc_freeze": True,
        "spin_us": 0,
    }
    loop = status["loop"]
    assert loop["late_tolerance_ms"] == 3.0
    assert loop["tick"]["n"] == status["ticks"] > 0
    assert loop["period"]["n"] == status["ticks"] - 1
    assert loop["tick"]["p50_ms"] <= loop["tick"]["p99_ms"] <= loop["tick"]["max_ms"] + 0.05
    assert status["uart_writes"]["nonblocking"] is True
    assert status["uart_writes"]["dropped_writes"] == 0


def test_late_tolerance_in_the_configuration_file(tmp_path) -> None:
    good = tmp_path / "good.toml"
    good.write_text('late_tolerance_s = 0.004\n[ports]\nuart = "pty"\n')
    out = subprocess.run(
        [sys.executable, "-m", "rdm.cli", "config", "check", str(good)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert out.returncode == 0, out.stderr
    assert json.loads(out.stdout)["config"]["late_tolerance_s"] == 0.004
    bad = tmp_path / "bad.toml"
    bad.write_text("late_tolerance_s = -1.0\n")
    out = subprocess.run(
        [sys.executable, "-m", "rdm.cli", "config", "check", str(bad)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert out.returncode != 0
    assert "Traceback" not in out.stderr
    assert "late_tolerance_s" in out.stderr and "bad.toml" in out.stderr


def test_the_spin_is_in_the_status_and_validated() -> None:
    out = onboard("--spin-us", "500")
    assert out.returncode == 0, out.stderr
    status = json.loads(out.stdout.strip().splitlines()[-1])
    assert status["realtime"]["spin_us"] == 500
    assert status["ticks"] > 0
    for bad, says in (("-1", "-1 must be 0..5000"), ("5001", "5001 must be 0..5000"),
                      ("0.5", "'0.5': not an integer")):  # fmt: skip
        out = onboard("--spin-us", bad)
        assert out.returncode == 2 and "Traceback" not in out.stderr, out.stderr
        assert f"argument --spin-us: {says}" in out.stderr
