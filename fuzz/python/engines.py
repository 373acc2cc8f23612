"""The two ways the Python targets are run.

* :func:`run_mutations`: seeded mutation of the corpus (bit flips, byte sets, inserts,
  deletes, repeats, splices) mixed with the target's structure-aware generator. No
  coverage feedback; deterministic for a seed. The CI short form uses it in-process; the
  campaign uses it for ``isolated`` targets, in a child process that the parent restarts
  when it dies, so a native crash is reported with the input that caused it.
* :func:`atheris_main`: coverage-guided (libFuzzer through atheris), the rdm modules
  instrumented; used by the campaign for every target that is not ``isolated``.

Both give each input a time limit (a hang is an input still running after it) and count
known open findings (``fuzz_targets.known``) without stopping.
"""

from __future__ import annotations

import json
import os
import random
import signal
import struct
import subprocess
import sys
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
INTERESTING = (0x00, 0x01, 0x02, 0x03, 0x10, 0x7F, 0x80, 0xFE, 0xFF)


class Hang(Exception):
    """An input that ran past the time limit."""


def _alarm(_signum: int, _frame: Any) -> None:
    raise Hang()


def mutate(rng: random.Random, data: bytes, corpus: list[bytes], max_len: int) -> bytes:
    """One to four random edits of ``data`` (splices take bytes from ``corpus``)."""
    out = bytearray(data)
    for _ in range(rng.randint(1, 4)):
        op = rng.randrange(9)
        at = rng.randrange(len(out) + 1)
        if op == 0 and out:
            out[min(at, len(out) - 1)] ^= 1 << rng.randrange(8)
        elif op == 1 and out:
            out[min(at, len(out) - 1)] = rng.choice(INTERESTING)
        elif op == 2 and out:
            out[min(at, len(out) - 1)] = rng.randrange(256)
        elif op == 3:
            out[at:at] = bytes(rng.randrange(256) for _ in range(rng.randint(1, 8)))
        elif op == 4 and out:
            del out[at : at + rng.randint(1, 16)]
        elif op == 5 and out:
            start = rng.randrange(len(out))
            piece = out[start : start + rng.randint(1, 32)]
            out[at:at] = piece * rng.choice((1, 2, 3, 8, 100, 400))
        elif op == 6 and corpus:
            other = rng.choice(corpus)
            start = rng.randrange(len(other) + 1)
            out[at:at] = other[start : start + rng.randint(1, 64)]
        elif op == 7 and out:
            del out[at:]
        elif op == 8 and out:
            n = rng.choice((1, 2, 4, 8))
            value = rng.choice((0, 1, 2 ** (8 * n - 1) - 1, 2 ** (8 * n - 1), 2 ** (8 * n) - 1))
            out[at : at + n] = value.to_bytes(n, "little")
    return bytes(out[:max_len])


@dataclass
class Outcome:
    """What running one target gave."""

    runs: int = 0
    crashes: list[str] = field(default_factory=list)
    hangs: int = 0
    findings: Counter = field(default_factory=Counter)  # kind -> count
    known: Counter = field(default_factory=Counter)  # known name -> count
    reproducers: list[bytes] = field(default_factory=list)  # the first few failing inputs

    def record(self, kind: str, message: str, data: bytes) -> None:
        if kind == "crash":
            self.crashes.append(message)
        elif kind == "hang":
            self.hangs += 1
        else:
            self.findings[kind] += 1
        if len(self.reproducers) < 8:
            self.reproducers.append(data)


def run_one(target: Any, data: bytes, timeout: float) -> tuple[str, str]:
    """``("", "")`` when the input passes, else ``(kind, message)``: ``hang``, ``crash``,
    a finding kind, or ``known:<name>``."""
    from fuzz_targets.base import Finding
    from fuzz_targets.known import classify

    old = signal.signal(signal.SIGALRM, _alarm)
    start = time.monotonic()
    outer, _ = signal.setitimer(signal.ITIMER_REAL, timeout)  # a caller's timer (pytest-timeout)
    try:
        target.check(data)
    except Hang:
        return "hang", f"over {timeout} s"
    except Exception as exc:  # a finding, or a crash (an exception it should not raise)
        known = classify(target.name, exc, data, None)
        if known:
            return f"known:{known}", str(exc)[:200]
        if isinstance(exc, Finding):
            return exc.kind, f"{type(exc).__name__}: {exc}"
        return "crash", f"{type(exc).__name__}: {str(exc)[:300]}"
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)
        if outer > 0:  # give the caller's timer back what is left of it
            signal.setitimer(signal.ITIMER_REAL, max(outer - (time.monotonic() - start), 1e-3))
    return "", ""


def inputs(target: Any, corpus: list[bytes], runs: int, seed: int, max_len: int):
    """``runs`` inputs: mutations of the corpus, and the target's own structure-aware
    inputs for a quarter of them when it has a generator."""
    rng = random.Random(seed)
    pool = corpus or [b""]
    for _ in range(runs):
        if target.generate is not None and rng.random() < 0.25:
            data = target.generate(rng)
            if rng.random() < 0.5:
                data = mutate(rng, data, pool, max(max_len, len(data)))
            yield data
        else:
            yield mutate(rng, rng.choice(pool), pool, max_len)


def run_mutations(
    target: Any,
    corpus: list[bytes],
    runs: int,
    *,
    seed: int = 0,
    timeout: float = 10.0,
    max_len: int = 4096,
    progress: Callable[[int], None] | None = None,
) -> Outcome:
    """Run ``runs`` inputs of :func:`inputs`, in this process or (``target.isolated``) in
    a worker process restarted after each death."""
    out = Outcome()
    worker = _Worker(target.name, timeout) if target.isolated else None
    try:
        for k, data in enumerate(inputs(target, corpus, runs, seed, max_len)):
            kind, message = worker.run(data) if worker else run_one(target, data, timeout)
            out.runs += 1
            if kind.startswith("known:"):
                out.known[kind[6:]] += 1
            elif kind:
                out.record(kind, message, data)
            if progress is not None and k % 10_000 == 0:
                progress(k)
    finally:
        if worker is not None:
            worker.close()
    return out


# -- the worker process of isolated targets ----------------------------------------------
class _Worker:
    """A child process running one target: the parent sends length-prefixed inputs on its
    stdin and reads one JSON line per input; a child that dies is reported as a crash of
    the input it was given, classified by ``known.classify`` with its signal."""

    def __init__(self, name: str, timeout: float) -> None:
        self.name = name
        self.timeout = timeout
        self.proc: subprocess.Popen | None = None

    def _start(self) -> subprocess.Popen:
        return subprocess.Popen(
            [sys.executable, str(HERE / "fuzz.py"), "_worker", self.name, str(self.timeout)],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,
        )

    def run(self, data: bytes) -> tuple[str, str]:
        if self.proc is None or self.proc.poll() is not None:
            self.proc = self._start()
        proc = self.proc
        assert proc.stdin is not None and proc.stdout is not None
        try:
            proc.stdin.write(struct.pack("<I", len(data)) + data)
            proc.stdin.flush()
            line = proc.stdout.readline()
        except BrokenPipeError:
            line = b""
        if line:
            kind, message = json.loads(line)
            return kind, message
        code = proc.wait()
        self.proc = None
        sig = -code if code < 0 else None
        from fuzz_targets.known import classify

        known = classify(self.name, None, data, sig)
        if known:
            return f"known:{known}", f"signal {sig}"
        return "crash", f"worker died: exit {code}" + (f" (signal {sig})" if sig else "")

    def close(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            assert self.proc.stdin is not None
            self.proc.stdin.close()
            self.proc.wait(timeout=30)


def worker_main(name: str, timeout: float) -> None:
    """The child side of :class:`_Worker`."""
    from fuzz_targets import TARGETS

    target = TARGETS[name]
    stdin, stdout = sys.stdin.buffer, sys.stdout.buffer
    while True:
        head = stdin.read(4)
        if len(head) < 4:
            return
        data = stdin.read(struct.unpack("<I", head)[0])
        kind, message = run_one(target, data, timeout)
        stdout.write(json.dumps([kind, message]).encode() + b"\n")
        stdout.flush()


# -- atheris --------------------------------------------------------------------------------
def atheris_main(name: str, stats_path: str, timeout: float, argv: list[str]) -> None:
    """Run target ``name`` under atheris (libFuzzer flags in ``argv``). Counts every input
    and every known finding in ``stats_path`` (JSON, rewritten every 2 s and before a
    crash is reported); any other exception or finding is left to libFuzzer, which stops
    and writes the input to its artifact prefix."""
    import atheris

    with atheris.instrument_imports(include=["rdm"]):
        from fuzz_targets import TARGETS

    from fuzz_targets.known import classify

    target = TARGETS[name]
    stats: dict[str, Any] = {"runs": 0, "known": {}}
    last = [time.monotonic()]

    def save() -> None:
        tmp = stats_path + ".tmp"
        with open(tmp, "w") as fh:
            json.dump(stats, fh)
        os.replace(tmp, stats_path)

    def one_input(data: bytes) -> None:
        stats["runs"] += 1
        try:
            target.check(data)
        except Exception as exc:
            known = classify(name, exc, data, None)
            if not known:
                save()
                raise
            stats["known"][known] = stats["known"].get(known, 0) + 1
            save()
        if time.monotonic() - last[0] > 2.0:
            last[0] = time.monotonic()
            save()

    kwargs: dict[str, Any] = {}
    if target.generate is not None:
        # structure-aware inputs for a quarter of the mutations, libFuzzer's own for the rest
        def mutator(data: bytes, max_size: int, seed: int) -> bytes:
            rng = random.Random(seed)
            if rng.random() < 0.25:
                return target.generate(rng)[:max_size]
            return atheris.Mutate(data, max_size)

        kwargs["custom_mutator"] = mutator
    atheris.Setup([sys.argv[0], *argv, f"-timeout={max(1, int(timeout))}"], one_input, **kwargs)
    try:
        atheris.Fuzz()
    finally:
        save()
