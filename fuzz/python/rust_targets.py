"""The Rust targets of the campaign: ``cargo +nightly fuzz run`` (libFuzzer, ASan) of the
crate in ``fuzz/``, restarted after a crash until the runs are done, each crash's input
kept and classified (``fuzz_targets.known``; the Rust target ``description`` shares the
Python target's known findings and input format)."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path
from typing import Any

FUZZ = Path(__file__).resolve().parent.parent
RUST_TARGETS = ("rosserial_scan", "neuron_frame", "leptrino_ok_run", "description")
#: libFuzzer's -max_len per target (the description's macro makes long texts of short inputs).
MAX_LEN = {"description": 16384}
_PROGRESS = re.compile(rb"^#(\d+)\s+\w+\s+cov: (\d+) ft: (\d+)", re.M)
_DONE = re.compile(rb"Done (\d+) runs in (\d+) second")


def seeds(target: str) -> list[bytes]:
    """Golden-vector seeds of a Rust target (``fuzz/src/<target>.rs`` gives the format)."""
    from fuzz_targets import leptrino, neuron, rosserial
    from fuzz_targets.description import seeds as description_seeds

    if target == "rosserial_scan":
        golden = rosserial._golden()
        frames = [bytes.fromhex(v["hex"]) for v in golden["topics"]]
        frames += [bytes.fromhex(v["hex"]) for v in golden["bad_frames"] + golden["reserved"]]
        out = [bytes([sel]) + f for f in frames for sel in (1, 6)]
        return out + [bytes([sel]) + b"".join(frames[:12]) for sel in range(8)]
    if target == "neuron_frame":
        return [bytes([i & 0xFF, i >> 8]) + p for i, p, _ in neuron._vectors()]
    if target == "leptrino_ok_run":
        frames = leptrino._vectors()
        samples = [f for f in frames if len(f) > 24]
        return [*frames, b"".join(samples), b"".join(samples) + frames[0] + b"".join(samples)]
    return list(description_seeds())


def _classify(target: str, text: str, artifact: Path | None) -> tuple[str, str]:
    """``(kind, known name)`` of a stopped run."""
    from fuzz_targets.known import classify

    if "ERROR: libFuzzer: timeout" in text or "ALARM: working on the last Unit" in text:
        return "hang", ""
    if "out-of-memory" in text:
        return "oom", ""
    panic = re.search(r"panicked at [^\n]*\n([^\n]*)", text)
    message = panic.group(1) if panic else ""
    for prefix, kind in (("bad frame accepted", "bad_frame_accepted"),
                         ("not canonical", "not_canonical"), ("non-finite", "non_finite"),
                         ("wrong rejection", "wrong_rejection")):  # fmt: skip
        if message.startswith(prefix):
            return kind, ""
    data = artifact.read_bytes() if artifact is not None and artifact.exists() else b""
    signal = 11 if ("stack-overflow" in text or "deadly signal" in text) else None
    if target == "description" and signal is not None:
        return "crash", classify("description", None, data, signal)
    return "crash", ""


def run(target: str, runs: int, timeout: float, seed: int, max_restarts: int = 50) -> dict:
    """``runs`` inputs of the Rust target, restarting after each crash."""
    work = FUZZ / "out" / target
    (work / "corpus").mkdir(parents=True, exist_ok=True)
    artifacts = work / "artifacts"
    artifacts.mkdir(parents=True, exist_ok=True)
    total: dict[str, Any] = {"target": target, "engine": "cargo-fuzz", "requested": runs,
                             "runs": 0, "cov": None, "ft": None, "known": {}, "crashes": [],
                             "hangs": 0, "findings": {}, "peak_rss_mb": None}  # fmt: skip
    restarts = 0
    while total["runs"] < runs and restarts <= max_restarts:
        left = runs - total["runs"]
        proc = subprocess.run(
            ["cargo", "+nightly", "fuzz", "run", target, str(work / "corpus"),
             str(FUZZ / "corpus" / target), "--", f"-runs={left}", f"-seed={seed + restarts}",
             f"-max_len={MAX_LEN.get(target, 4096)}", f"-timeout={max(1, int(timeout))}",
             "-rss_limit_mb=2048", "-print_final_stats=1",
             f"-artifact_prefix={artifacts}/"],
            cwd=FUZZ, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, check=False,
        )  # fmt: skip
        out = proc.stdout
        (work / "last.log").write_bytes(out[-200_000:])
        done = _DONE.search(out)
        progress = _PROGRESS.findall(out)
        ran = int(done.group(1)) if done else int(progress[-1][0]) if progress else 0
        rss = re.search(rb"stat::peak_rss_mb:\s*(\d+)", out)
        total["runs"] += ran
        if progress:
            total["cov"] = max(total["cov"] or 0, int(progress[-1][1]))
            total["ft"] = max(total["ft"] or 0, int(progress[-1][2]))
        if rss:
            total["peak_rss_mb"] = max(total["peak_rss_mb"] or 0, int(rss.group(1)))
        if proc.returncode == 0 and done:
            break
        text = out.decode("utf-8", "replace")
        written = re.search(r"Test unit written to (\S+)", text)
        artifact = Path(written.group(1)) if written else None
        kind, known = _classify(target, text, artifact)
        if known:
            total["known"][known] = total["known"].get(known, 0) + 1
        elif kind == "crash":
            total["crashes"].append({"artifact": str(artifact), "message": text[-1500:]})
        elif kind == "hang":
            total["hangs"] += 1
        else:
            total["findings"][kind] = total["findings"].get(kind, 0) + 1
        restarts += 1
        if ran == 0 and artifact is None:
            total["crashes"].append({"artifact": None, "message": text[-1500:]})
            break
    return total
