"""``rdm decode`` throughput and memory: the ``decode`` benchmark case.

Each measurement writes a capture to a temporary folder and decodes it with ``rdm decode``
(text output to ``/dev/null``) in a child process, which reports its wall and CPU time around
the decode and its peak RSS (:func:`peak_rss_kb`). The same child decoding a capture of a few bytes
gives the baseline RSS (interpreter, numpy, the extension), so the reported growth is what the
capture's size adds. The summary is microseconds per MB of capture over the runs
(``--iterations N``: N decodes of a small capture in one child).

* ``decode_uart_garbage``: a UART capture of 0xFF bytes (every byte a rejected frame, one line
  each) followed by random bytes;
* ``decode_leptrino``: a Leptrino capture of continuous-output samples of random counts
  (some DLE stuffed) with a little garbage between blocks. Target: 10 MB/s (the UART capture:
  1 MB/s).
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from rdm.bench.cases import Case, Context, Measurement, Target, register
from rdm.bench.statistics import summarize_ns

#: The child: decode argv[2:] with stdout to /dev/null, write the figures to argv[1].
_CHILD = """
import json, os, sys, time
from rdm.cli import main
from rdm.bench.decode import peak_rss_kb
out, repeats, args = sys.argv[1], int(sys.argv[2]), sys.argv[3:]
sys.stdout = open(os.devnull, "w")
walls, cpus = [], []
for _ in range(repeats):
    w0, c0 = time.perf_counter(), time.process_time()
    rc = main(["decode", *args])
    sys.stdout.flush()
    walls.append(time.perf_counter() - w0)
    cpus.append(time.process_time() - c0)
    if rc != 0:
        break
with open(out, "w") as fh:
    json.dump({"rc": rc, "walls": walls, "cpus": cpus, "maxrss_kb": peak_rss_kb()}, fh)
"""


def peak_rss_kb() -> int:
    """Peak resident set of this process in kB: ``VmHWM`` of ``/proc/self/status`` (the
    high-water mark of this program's own memory). ``ru_maxrss`` is the fallback where there
    is no ``/proc``; on Linux it also keeps the parent's size across the fork and exec that
    started the process, so it is not used there."""
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1])
    except OSError:
        pass
    import resource

    return int(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)


MB = 1e6
#: Leptrino throughput target (MB of capture per second).
LEPTRINO_TARGET_MB_S = 10.0
#: Lower bound on the garbage UART capture's throughput: one line per rejected 0xFF costs,
#: the rest is the scan.
UART_GARBAGE_TARGET_MB_S = 1.0


def decode_in_child(capture: Path, repeats: int = 1) -> dict[str, Any]:
    """``rdm decode capture`` ``repeats`` times in one child process: each decode's wall s
    and CPU s (``walls``, ``cpus``) and the child's peak RSS in kB (``maxrss_kb``)."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "figures.json"
        cmd = [sys.executable, "-c", _CHILD, str(out), str(repeats), str(capture)]
        done = subprocess.run(cmd, capture_output=True, text=True, check=False)
        if done.returncode != 0 or not out.is_file():
            raise RuntimeError(f"rdm decode {capture.name} failed: {done.stderr.strip()[-300:]}")
        figures: dict[str, Any] = json.loads(out.read_text())
    if figures["rc"] != 0:
        raise RuntimeError(f"rdm decode {capture.name} exited {figures['rc']}")
    return figures


def leptrino_capture(n_frames: int, seed: int = 0) -> bytes:
    """Continuous-output sample frames of random counts (some DLE stuffed), with a few bytes
    of garbage after every 1000 frames."""
    from rdm.protocol.leptrino import ForceData, encode_response

    rng = np.random.default_rng(seed)
    counts = rng.integers(-3000, 3000, size=(1000, 6))
    block = b"".join(
        encode_response(ForceData(tuple(int(c) for c in row), 250, 0, 0, 0)) for row in counts
    )
    garbage = bytes(rng.integers(0, 256, 7, dtype=np.uint8).tolist()).replace(b"\x10", b"\x11")
    blocks, rest = divmod(n_frames, 1000)
    return (block + garbage) * blocks + block[: 25 * rest]


def uart_garbage_capture(flood: int, random_bytes: int, seed: int = 0) -> bytes:
    """``flood`` bytes of 0xFF, then ``random_bytes`` random bytes."""
    rng = np.random.default_rng(seed)
    return b"\xff" * flood + rng.integers(0, 256, random_bytes, dtype=np.uint8).tobytes()


def _measure(
    ctx: Context, name: str, title: str, capture: bytes, suffix: str, targets: list[Target]
) -> Measurement:
    """Decode ``capture``: in full runs 3 children (quick: 1) of one decode each; with
    ``--iterations N``, one child decoding it N times (the caller makes it small)."""
    if ctx.iterations is not None:
        children, repeats = 1, ctx.iterations
    else:
        children, repeats = (1 if ctx.quick else 3), 1
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / f"capture{suffix}"
        path.write_bytes(capture)
        tiny = Path(tmp) / f"tiny{suffix}"
        tiny.write_bytes(capture[:64])
        base = decode_in_child(tiny)
        figures = []
        for k in range(children):
            ctx.progress(
                f"{name}: child {k + 1}/{children}, {repeats} x {len(capture) / MB:.2f} MB"
            )
            figures.append(decode_in_child(path, repeats))
    size_mb = len(capture) / MB
    walls = [w for f in figures for w in f["walls"]]
    cpus = [c for f in figures for c in f["cpus"]]
    wall, cpu = float(np.median(walls)), float(np.median(cpus))
    peak = max(f["maxrss_kb"] for f in figures) / 1024
    growth = peak - base["maxrss_kb"] / 1024
    notes = [
        f"{size_mb:.2f} MB capture: {size_mb / wall:.1f} MB/s wall, {size_mb / cpu:.1f} MB/s "
        f"per CPU s (median of {len(walls)})",
        f"peak RSS {peak:.0f} MB, {growth:.0f} MB above the same decode of a 64-byte capture",
    ]
    return Measurement(
        name,
        title,
        summarize_ns(np.array(walls) / size_mb * 1e9),
        1e6 / LEPTRINO_TARGET_MB_S,
        0,
        targets,
        {},
        notes,
    )


def run_decode(ctx: Context) -> list[Measurement]:
    """Throughput and peak memory of ``rdm decode`` on a garbage UART and a Leptrino capture."""
    if ctx.iterations is not None:  # many decodes of a small capture in one child
        flood, noise, frames = 2_000, 20_000, 800
    elif ctx.quick:
        flood, noise, frames = 200_000, 2_000_000, 160_000  # 2.2 MB, 4 MB
    else:
        flood, noise, frames = 2_000_000, 20_000_000, 800_000  # 22 MB, 20 MB
    uart = _measure(
        ctx,
        "decode_uart_garbage",
        "rdm decode: 0xFF flood and random bytes as UART, us per MB",
        uart_garbage_capture(flood, noise),
        ".bin",
        [Target("median_us", 1e6 / UART_GARBAGE_TARGET_MB_S)],
    )
    lep = _measure(
        ctx,
        "decode_leptrino",
        "rdm decode: Leptrino samples, us per MB",
        leptrino_capture(frames),
        ".lep",
        [Target("median_us", 1e6 / LEPTRINO_TARGET_MB_S)],
    )
    return [uart, lep]


register(
    Case(
        "decode",
        "rdm decode throughput and peak memory",
        run_decode,
        ("decode_uart_garbage", "decode_leptrino"),
        (),
    )
)
