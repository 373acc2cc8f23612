"""Client-side clock of rosserial: ROS time from the MCU millisecond tick plus a sync offset.

The client asks for time (topic 10, ``{0, 0}``) and remembers the tick of the request. On the
answer it sets ``now = answer + (tick_now - tick_at_request)``, i.e. it charges the whole round
trip to the way back, exactly like ``NodeHandle::syncTime`` (fact sheet sec. 1.3 item 4).
Ticks are uint32 milliseconds that wrap; differences are taken modulo 2**32.
"""

from __future__ import annotations

from rdm.protocol.rosserial.codec import RosTime

_MASK = 0xFFFFFFFF


def tick_diff(now_ms: int, then_ms: int) -> int:
    """``now - then`` in uint32 arithmetic, as the firmware computes it."""
    return (now_ms - then_ms) & _MASK


class ClientClock:
    """ROS time kept by the client; unsynchronised it counts from zero like the firmware."""

    def __init__(self) -> None:
        self._sync_tick = 0  # tick of the last time answer
        self._sync_ns = 0  # ROS time at that tick
        self._request_tick: int | None = None
        self.synced = False

    def request_sent(self, now_ms: int) -> None:
        """A time request left at tick ``now_ms`` (the firmware's ``rt_time``)."""
        self._request_tick = now_ms & _MASK

    def answer_received(self, answer: RosTime, now_ms: int) -> int:
        """Apply a time answer received at ``now_ms``; returns the round trip in ms."""
        rtt = 0 if self._request_tick is None else tick_diff(now_ms, self._request_tick)
        self._sync_ns = answer.to_ns() + rtt * 1_000_000
        self._sync_tick = now_ms & _MASK
        self.synced = True
        return rtt

    def now(self, now_ms: int) -> RosTime:
        """ROS time at tick ``now_ms``, counted from the last sync with a signed wrap-safe tick
        difference (the firmware's uint32 arithmetic would jump back 49.7 days at a wrap)."""
        if not self.synced:
            return RosTime.from_ns((now_ms & _MASK) * 1_000_000)
        # signed 32-bit tick difference and RosTime.from_ns inlined: 200+ stamps a second
        elapsed = ((now_ms - self._sync_tick + 2**31) & _MASK) - 2**31
        ns = self._sync_ns + elapsed * 1_000_000
        return RosTime(*divmod(ns, 1_000_000_000)) if ns > 0 else RosTime(0, 0)
