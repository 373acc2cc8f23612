"""A byte link for node tests: the test feeds what the node reads, and it records what the
node writes (shared by the onboard fast-path tests)."""

from __future__ import annotations


class FedByteLink:
    """``read_available`` returns what the test put in ``pending``; ``write`` records."""

    def __init__(self) -> None:
        self.pending = b""
        self.written: list[bytes] = []

    def read_available(self) -> bytes:
        data, self.pending = self.pending, b""
        return data

    def write(self, data: bytes) -> int:
        self.written.append(bytes(data))
        return len(data)
