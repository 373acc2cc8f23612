"""The ground station's heartbeat as the robot sees it.

Every authenticated, fresh datagram from the ground station refreshes the heartbeat
(``rdm ctl --heartbeat HZ`` sends one every 1/HZ s). The watch is armed by the first one;
from then on, more than ``timeout_s`` without one is a *loss* (reported once), and the next
datagram after a loss a *restore* (reported once). JSK's navigator lands when its joystick
has been silent for more than 2.0 s (``joy_stick_heart_beat_du``, a strict comparison,
jsk-flight-navigation.md sec. 5.1); the ground link uses the same rule with its own timeout.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

#: Seconds without a ground datagram before the ground station counts as lost.
#: ASSUMPTION: 1.0 s, half JSK's joystick timeout (2.0 s): the ground link is the operator's
#: only link, and at ``rdm ctl --heartbeat 5`` it takes five lost heartbeats in a row.
GROUND_TIMEOUT_S = 1.0


@dataclass
class Heartbeat:
    """Loss/restore detection on times passed in (node time, s)."""

    timeout_s: float = GROUND_TIMEOUT_S
    #: Node time of the last refresh (None: never refreshed, the watch is not armed).
    last: float | None = None
    lost: bool = False
    #: Losses detected so far.
    trips: int = 0
    #: Restores detected so far.
    restores: int = 0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.timeout_s) and self.timeout_s > 0):
            raise ValueError(f"ground timeout {self.timeout_s!r}: must be finite and > 0 s")

    @property
    def armed(self) -> bool:
        """True once the first refresh has come."""
        return self.last is not None

    def refresh(self, now: float) -> bool:
        """A ground datagram at ``now``; True if this restores a lost link."""
        self.last = now
        if self.lost:
            self.lost = False
            self.restores += 1
            return True
        return False

    def check(self, now: float) -> bool:
        """True exactly once per loss: armed, not lost yet, and ``now - last > timeout_s``."""
        if self.last is None or self.lost or not now - self.last > self.timeout_s:
            return False
        self.lost = True
        self.trips += 1
        return True

    def age(self, now: float) -> float | None:
        """Seconds since the last refresh (None before the first)."""
        return None if self.last is None else now - self.last
