"""Golden runs for tests: SHA-256 digests of what a run produced, kept in a JSON file under
``tests/data`` and checked by name. ``RDM_WRITE_GOLDEN=1`` records the digests of the runs
that execute (only after a deliberate change of the simulated bytes; say why in the commit).
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

DATA = Path(__file__).parent / "data"
_WRITTEN: set[tuple[str, str]] = set()  # (file, run) recorded by this process


def sha(data: bytes) -> str:
    """SHA-256 of ``data`` as hex."""
    return hashlib.sha256(data).hexdigest()


def check(file: str, name: str, digests: dict[str, str]) -> None:
    """``digests`` equal the golden digests of run ``name`` in ``tests/data/<file>``
    (recorded there first with ``RDM_WRITE_GOLDEN=1``; a run checked twice in one process,
    e.g. two forms of one path, is recorded once and the second check compares)."""
    path = DATA / file
    golden = json.loads(path.read_text()) if path.exists() else {}
    if os.environ.get("RDM_WRITE_GOLDEN") and (file, name) not in _WRITTEN:
        _WRITTEN.add((file, name))
        golden[name] = digests
        path.write_text(json.dumps(golden, indent=1, sort_keys=True) + "\n")
    want = golden.get(name)
    assert want is not None, f"{file} holds no run {name!r}"
    assert sorted(digests) == sorted(want), name
    for key in want:
        assert digests[key] == want[key], (name, key)
