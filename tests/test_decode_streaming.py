"""``rdm decode`` streams: output byte-identical to the golden output of the whole-capture
decoders, in any chunking, valid JSON lines, and memory that does not grow with the capture.

The golden files in ``tests/data/decode`` were written by ``rdm decode`` when it still read
the whole capture and built every record before printing (captures: real frames of a
simulated mission cut and mixed with random bytes, a 0xFF run, corrupt, truncated and DLE
stuffed frames, and bad candump lines).
"""

from __future__ import annotations

import json
import random
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import rdm.commands.decode as decode_cmd
import rdm.protocol.leptrino_capture as lepcap
from rdm.cli import main
from rdm.commands.decode import format_record
from rdm.commands.decode_lines import force_run_lines
from rdm.protocol.leptrino import LeptrinoStreamParser, decode_leptrino

DATA = Path(__file__).resolve().parent / "data" / "decode"
CAPTURES = ("mixed.bin", "mixed.lep", "mixed.log")


def _decode(capsys: pytest.CaptureFixture[str], path: Path, *args: str) -> tuple[str, str]:
    assert main(["decode", str(path), *args]) == 0
    out = capsys.readouterr()
    return out.out, out.err


@pytest.mark.parametrize("name", CAPTURES)
def test_text_output_is_the_golden_output(name, capsys):
    out, err = _decode(capsys, DATA / name)
    assert out == (DATA / f"{name}.txt").read_text()
    assert err == (DATA / f"{name}.summary").read_text()


@pytest.mark.parametrize("name", CAPTURES)
def test_json_lines_are_the_golden_output_and_valid_json(name, capsys):
    out, err = _decode(capsys, DATA / name, "--json")
    golden = (DATA / f"{name}.jsonl").read_text()
    assert out == golden
    assert err == (DATA / f"{name}.summary").read_text()
    records = [json.loads(line) for line in out.splitlines()]
    assert len(records) == golden.count("\n")
    summary = err.split(": ", 1)[1]
    ok = sum(1 for r in records if r["ok"])
    assert summary.startswith(f"{ok} records decoded, {len(records) - ok} bad")


@pytest.mark.parametrize("chunk", [1, 7, 25, 1000])
@pytest.mark.parametrize("name", ("mixed.bin", "mixed.lep"))
def test_any_chunking_gives_the_golden_output(name, chunk, capsys, monkeypatch):
    """Frames, skipped runs and Leptrino sample runs cut by chunk boundaries; small scan
    windows and batches so runs are split and joined."""
    monkeypatch.setattr(decode_cmd, "CHUNK_BYTES", chunk)
    monkeypatch.setattr(decode_cmd, "LEPTRINO_CHUNK_BYTES", chunk)
    monkeypatch.setattr(lepcap, "_WINDOW", 60)
    monkeypatch.setattr(lepcap, "BATCH_FRAMES", 3)
    for args, suffix in (((), ".txt"), (("--json",), ".jsonl")):
        out, _ = _decode(capsys, DATA / name, *args)
        assert out == (DATA / f"{name}{suffix}").read_text()


def _leptrino_mix(seed: int) -> bytes:
    """Real sample frames (some stuffed), random bytes, DLE STX floods and cut frames."""
    rng = random.Random(seed)
    lep = (DATA / "mixed.lep").read_bytes()
    frames = lep[:2950]
    parts = []
    for _ in range(40):
        k = rng.randrange(6)
        if k == 0:
            parts.append(bytes(rng.randrange(256) for _ in range(rng.randrange(1, 60))))
        elif k == 1:
            parts.append(b"\x10\x02\x14" * rng.randrange(1, 20))
        elif k == 2:
            a = rng.randrange(len(frames))
            parts.append(frames[a : a + rng.randrange(1, 80)])
        else:
            a = 25 * rng.randrange(len(frames) // 25 - 10)
            parts.append(frames[a : a + 25 * rng.randrange(1, 10)])
    return b"".join(parts)


@pytest.mark.parametrize("seed", range(6))
def test_leptrino_batches_hold_the_byte_parsers_records(seed):
    """The batched decoder against the byte-by-byte state machine on the whole capture:
    the same records and the same counters, garbage counted as discarded bytes."""
    data = _leptrino_mix(seed)
    whole = LeptrinoStreamParser()
    want = list(decode_leptrino(data, parser=whole))
    for chunk in (1, 13, 4096):
        parser = LeptrinoStreamParser()
        got = []
        pieces = (data[i : i + chunk] for i in range(0, len(data), chunk))
        for item in lepcap.iter_leptrino_records(pieces, parser=parser):
            got.extend(item.records() if isinstance(item, lepcap.ForceRun) else [item])
        assert got == want
        assert parser.discarded_bytes == whole.discarded_bytes > 0
        assert parser.errors == whole.errors
        assert parser.frames == whole.frames


_CHILD = """
import os, sys
from rdm.bench.decode import peak_rss_kb
from rdm.cli import main
from rdm.commands.decode import format_record
from rdm.commands.decode_lines import force_run_lines
sys.stdout = open(os.devnull, "w")
rc = main(["decode", sys.argv[1]]) if sys.argv[1] != "-" else 0
hold = bytearray(int(sys.argv[2]) << 20)
hold[:: 1 << 12] = b"\\x01" * len(hold[:: 1 << 12])  # touched: resident
sys.stdout.flush()
print("PEAK", rc, peak_rss_kb(), file=sys.__stderr__)
"""


def _peak_rss_mb(capture: Path | str, hold_mb: int = 0) -> float:
    """Peak RSS of a fresh interpreter that decodes ``capture`` ("-": nothing), then holds
    ``hold_mb`` MB."""
    done = subprocess.run(
        [sys.executable, "-c", _CHILD, str(capture), str(hold_mb)],
        capture_output=True,
        text=True,
        check=True,
    )
    line = [x for x in done.stderr.splitlines() if x.startswith("PEAK")][-1]
    _, rc, kb = line.split()
    assert rc == "0"
    return int(kb) / 1024


def test_the_peak_rss_measure_sees_growth():
    """The measure below can fail: 60 MB held in the child shows as 60 MB more."""
    growth = _peak_rss_mb("-", 60) - _peak_rss_mb("-", 0)
    assert 55.0 < growth < 70.0


@pytest.mark.parametrize("suffix", [".bin", ".lep"])
def test_memory_does_not_grow_with_a_20_mb_garbage_capture(tmp_path, suffix):
    """Peak RSS of a child decoding 20 MB of random bytes (with 0xFF and DLE runs) against the
    same child decoding 64 of them: the growth stays far below the capture's size."""
    rng = random.Random(28)
    block = bytes(rng.randrange(256) for _ in range(1 << 16))
    block += b"\xff" * 512 + b"\x10\x02" * 256
    data = block * (20_000_000 // len(block) + 1)
    big = tmp_path / f"garbage{suffix}"
    big.write_bytes(data)
    small = tmp_path / f"small{suffix}"
    small.write_bytes(data[:64])
    growth = _peak_rss_mb(big) - _peak_rss_mb(small)
    assert growth < 12.0, f"peak RSS grew {growth:.1f} MB for a {len(data) / 1e6:.0f} MB capture"


def test_force_run_lines_hold_every_int16_and_offset_width():
    """Column-wise Leptrino lines against json.loads and struct.unpack of each payload, and
    the text line against format_record of the parsed record (json.dumps's formatting)."""
    rng = np.random.default_rng(5)
    n = 3000
    payloads = rng.integers(0, 256, (n, 20), dtype=np.uint8)
    payloads[:, 0], payloads[:, 2], payloads[:, 3] = 20, 0x32, 0
    extremes = np.array([-32768, 32767, -1, 0, 1, -10, 10, 9999, -10000], np.int16)
    counts = payloads[:, 4:18].copy().view("<i2")
    counts[: len(extremes), :] = extremes[:, None]
    payloads[:, 4:18] = counts.view(np.uint8)
    offsets = np.sort(rng.integers(0, 2**40, n)).astype(np.int64)
    offsets[:3] = (0, 9, 10)
    run = lepcap.ForceRun(offsets, payloads)
    json_lines = force_run_lines(run, True).splitlines()
    text_lines = force_run_lines(run, False).splitlines()
    assert len(json_lines) == len(text_lines) == n
    for k in range(n):
        rec = json.loads(json_lines[k])
        data = payloads[k].tobytes()
        *raw, temperature, status = struct.unpack("<6hhBx", data[4:])
        assert rec == {
            "offset": int(offsets[k]),
            "kind": "force_data",
            "ok": True,
            "error": None,
            "payload": data.hex(),
            "raw": raw,
            "temperature": temperature,
            "status": status,
            "result": data[3],
            "term_no": data[1],
        }
        assert text_lines[k] == format_record(rec)
