"""The reference runs' bytes (scripts/reference_manifest.py): every scenario for two seeds, the
candump log, every UART capture and time index, the signals MCAP and the summary (wall-clock
fields aside) hash to the SHA-256 values in tests/data/reference_manifest.json.

A change of any of those bytes fails here and names the run and file: a restructuring keeps
them; a change of behaviour regenerates the manifest (``python scripts/reference_manifest.py
write``) with the reason in its commit.
"""

from __future__ import annotations

import importlib.util
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _manifest_module():
    spec = importlib.util.spec_from_file_location(
        "reference_manifest", ROOT / "scripts" / "reference_manifest.py"
    )
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules["reference_manifest"] = module
    spec.loader.exec_module(module)
    return module


def test_reference_runs_keep_their_bytes(tmp_path):
    rm = _manifest_module()
    expected = json.loads((ROOT / "tests" / "data" / "reference_manifest.json").read_text())
    assert set(expected) == {f"{s}-seed{k}" for s in rm.RUNS for k in rm.SEEDS}
    for run, files in expected.items():  # each run holds its wires, not only a summary
        assert "can.log" in files and "signals.mcap" in files and "summary.json" in files, run
        assert any(rel.startswith("uart/spinal.") for rel in files), run
    actual = rm.run_all(tmp_path)
    assert rm.compare(expected, actual) == []


def test_the_comparison_names_a_changed_file(tmp_path):
    rm = _manifest_module()
    run = tmp_path / "r"
    (run / "uart").mkdir(parents=True)
    (run / "can.log").write_bytes(b"(0.001000) vcan0 123#00\n")
    (run / "uart" / "spinal.device_tx.bin").write_bytes(b"\xff\xfe")
    (run / "summary.json").write_text(json.dumps({"a": 1, "wall_s": 0.5}))
    before = rm.digest_folder(run)
    (run / "summary.json").write_text(json.dumps({"a": 1, "wall_s": 9.0}))
    assert rm.digest_folder(run) == before  # the wall clock is not part of the run
    (run / "uart" / "spinal.device_tx.bin").write_bytes(b"\xff\xff")
    lines = rm.compare({"x": before}, {"x": rm.digest_folder(run)})
    assert len(lines) == 1 and lines[0].startswith("x/uart/spinal.device_tx.bin:")
