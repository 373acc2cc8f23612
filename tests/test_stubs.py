"""``python/rdm/_rdm.pyi`` against the compiled module: mypy's stubtest imports ``rdm._rdm`` and
compares every class, function, method, property and constructor signature (names, kinds and
defaults of parameters, ``@final``) with the stub. A binding added, removed or changed
without its stub fails here. PEP 800 disjoint-base markers are not checked (every pyo3 class
is one; the stub does not mark them)."""

from __future__ import annotations

import subprocess
import sys


def test_the_stub_matches_the_compiled_module():
    cmd = [sys.executable, "-m", "mypy.stubtest", "rdm._rdm", "--ignore-disjoint-bases"]
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stdout[-4000:] + out.stderr[-2000:]
    assert "Success: no issues found in 1 module" in out.stdout
