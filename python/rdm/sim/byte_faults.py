"""Byte faults on a UART: bit errors, lost bytes and repeated bytes, for fault campaigns.

:class:`CorruptingLink` wraps a byte-link end (``read_available``, ``write``, ``close``) and
damages what it reads: each byte, independently with probability ``p``, has one random bit
flipped; each byte is lost with probability ``p``; each byte is repeated with probability ``p``
(in that order). A noisy cable or a marginal level shifter gives such faults; rosserial's
checksums must reject the damaged frames (docs/flying.md "Fault campaign"). The random stream
is seeded, so a run is reproducible.
"""

from __future__ import annotations

from typing import Any

import numpy as np


class CorruptingLink:
    """``link`` with every byte it reads exposed to bit flips, loss and repetition."""

    def __init__(self, link: Any, p: float, seed: int) -> None:
        if not 0.0 <= p <= 1.0:
            raise ValueError(f"CorruptingLink: p {p!r} not in [0, 1]")
        self.link = link
        self.p = float(p)
        self._rng = np.random.default_rng(seed)
        self.flipped = 0
        self.lost = 0
        self.repeated = 0

    def damage(self, data: bytes) -> bytes:
        """``data`` with this link's faults applied (counted)."""
        if not data or self.p == 0.0:
            return data
        rng = self._rng
        raw = np.frombuffer(data, dtype=np.uint8).copy()
        flip = rng.random(raw.size) < self.p
        raw[flip] ^= (1 << rng.integers(0, 8, size=int(flip.sum()))).astype(np.uint8)
        keep = rng.random(raw.size) >= self.p
        raw = raw[keep]
        repeat = (rng.random(raw.size) < self.p).astype(np.int64) + 1
        self.flipped += int(flip.sum())
        self.lost += int((~keep).sum())
        self.repeated += int((repeat > 1).sum())
        return np.repeat(raw, repeat).tobytes()

    def read_available(self) -> bytes:
        return self.damage(self.link.read_available())

    def write(self, data: bytes) -> int:
        return self.link.write(data)

    def close(self) -> None:
        self.link.close()

    def counts(self) -> dict[str, int]:
        """Bytes flipped, lost and repeated so far."""
        return {"flipped": self.flipped, "lost": self.lost, "repeated": self.repeated}
