"""A fast in-process CAN bus for lockstep simulation: a python-can ``BusABC`` subclass.

Semantics follow python-can's ``virtual`` bus (every bus on the same channel name receives every
frame another bus sends, in send order; a bus does not hear itself unless
``receive_own_messages``; receive filters honoured), with three differences that matter for
lockstep:

* **Timestamps come from the channel's simulated clock** (:class:`SimClock`, settable by the
  scheduler), never from ``time.time()``. Same inputs, same timestamps, same candump bytes.
* **One copy per send, not one deep copy per receiver.** The frame is copied once (the sender
  may reuse its object); every receiver gets that copy (a second one when the sender also hears
  itself, because ``is_rx`` differs). Receivers must treat received messages as read-only,
  which every node here does.
* **Filters are applied at delivery**, so a filtered frame never enters a receive queue.

Channels also accept *taps* (``add_tap``): callables that see every frame sent on the channel,
synchronously, before delivery (a candump capture uses one).

``recv(timeout=0)`` (what nodes use) never blocks. A positive or ``None`` timeout waits by polling
every 0.2 ms (for real-time use from threads); lockstep never waits.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable
from typing import Any

import can
from can import CanOperationError, Message

#: Poll interval of a blocking ``recv`` (only used when a timeout other than 0 is given).
_POLL_S = 0.0002


class SimClock:
    """A settable clock: ``clock()`` returns :attr:`now` (seconds). The lockstep scheduler sets
    it at every tick; the in-process CAN channel stamps frames with it."""

    __slots__ = ("now",)

    def __init__(self, now: float = 0.0) -> None:
        self.now = float(now)

    def __call__(self) -> float:
        return self.now

    def set(self, now: float) -> None:
        self.now = now


class _Channel:
    """The shared state of one channel name: attached buses, taps, clock."""

    __slots__ = ("buses", "clock", "frames", "name", "taps")

    def __init__(self, name: str) -> None:
        self.name = name
        self.buses: list[InProcessBus] = []
        self.taps: list[Callable[[Message], None]] = []
        self.clock: Callable[[], float] = SimClock()
        self.frames = 0


_channels: dict[str, _Channel] = {}
_lock = threading.RLock()


def _channel(name: str) -> _Channel:
    with _lock:
        ch = _channels.get(name)
        if ch is None:
            ch = _channels[name] = _Channel(name)
        return ch


def set_channel_clock(name: str, clock: Callable[[], float]) -> None:
    """Stamp every later frame on channel ``name`` with ``clock()`` (e.g. a :class:`SimClock`)."""
    if not callable(clock):
        raise TypeError(f"set_channel_clock: clock {clock!r} is not callable")
    _channel(name).clock = clock


def add_tap(name: str, tap: Callable[[Message], None]) -> None:
    """Call ``tap(msg)`` for every frame sent on channel ``name`` (msg is the delivered copy,
    stamped, ``is_rx`` True). Remove with :func:`remove_tap`."""
    if not callable(tap):
        raise TypeError(f"add_tap: {tap!r} is not callable")
    _channel(name).taps.append(tap)


def remove_tap(name: str, tap: Callable[[Message], None]) -> None:
    ch = _channels.get(name)
    if ch is not None and tap in ch.taps:
        ch.taps.remove(tap)


def channel_frame_count(name: str) -> int:
    """Frames sent on channel ``name`` since it was created."""
    ch = _channels.get(name)
    return 0 if ch is None else ch.frames


def _copy(msg: Message, stamp: float, channel: str, is_rx: bool) -> Message:
    # An independent frame without Message.__init__'s argument handling: every slot set
    # directly (the data as a fresh bytearray, as __init__ stores it).
    new = _new_message(Message)
    new.timestamp = stamp
    new.arbitration_id = msg.arbitration_id
    new.is_extended_id = msg.is_extended_id
    new.is_remote_frame = msg.is_remote_frame
    new.is_error_frame = msg.is_error_frame
    new.channel = channel
    new.dlc = msg.dlc
    new.data = bytearray(msg.data)
    new.is_fd = msg.is_fd
    new.is_rx = is_rx
    new.bitrate_switch = msg.bitrate_switch
    new.error_state_indicator = msg.error_state_indicator
    return new


_new_message = Message.__new__


class InProcessBus(can.BusABC):
    """One node's connection to an in-process channel (see the module doc).

    Args:
        channel: channel name; every bus of this process with the same name shares traffic.
        receive_own_messages: also deliver this bus's own frames to itself (``is_rx`` False).
        preserve_timestamps: keep the sender's ``msg.timestamp`` instead of the channel clock.
        can_filters: python-can filters (``[{"can_id":, "can_mask":, "extended":}]``).
        rx_queue_size: 0 = unbounded; else the oldest frame is dropped when full (counted in
            :attr:`rx_dropped`), as python-can's virtual bus with a bounded queue.
    """

    def __init__(
        self,
        channel: str = "inproc0",
        receive_own_messages: bool = False,
        preserve_timestamps: bool = False,
        can_filters: Any = None,
        rx_queue_size: int = 0,
        **kwargs: Any,
    ) -> None:
        if not isinstance(channel, str) or not channel:
            raise ValueError(f"InProcessBus: channel {channel!r} must be a non-empty string")
        if not isinstance(rx_queue_size, int) or rx_queue_size < 0:
            raise ValueError(f"InProcessBus: rx_queue_size {rx_queue_size!r} must be >= 0")
        self.channel_id = channel
        self.channel_info = f"in-process CAN channel {channel}"
        self.receive_own_messages = bool(receive_own_messages)
        self.preserve_timestamps = bool(preserve_timestamps)
        self._queue: deque[Message] = deque(maxlen=rx_queue_size or None)
        self.rx_dropped = 0
        self._open = True
        self._ch = _channel(channel)
        super().__init__(channel=channel, can_filters=can_filters, **kwargs)
        with _lock:
            self._ch.buses.append(self)

    # ------------------------------------------------------------------ python-can API
    def send(self, msg: Message, timeout: float | None = None) -> None:
        """Deliver ``msg`` to every other bus on the channel (and taps) now."""
        if not self._open:
            raise CanOperationError("Cannot operate on a closed bus")
        ch = self._ch
        stamp = msg.timestamp if self.preserve_timestamps else ch.clock()
        self._deliver(msg, _copy(msg, stamp, self.channel_id, True))

    def send_standard(self, arbitration_id: int, data: bytes) -> None:
        """``send(Message(arbitration_id=.., data=data, is_extended_id=False))`` without
        building the sender's message (a classic data frame; what the Neuron link sends)."""
        if not self._open:
            raise CanOperationError("Cannot operate on a closed bus")
        ch = self._ch
        new = _new_message(Message)
        new.timestamp = 0.0 if self.preserve_timestamps else ch.clock()
        new.arbitration_id = arbitration_id
        new.is_extended_id = False
        new.is_remote_frame = False
        new.is_error_frame = False
        new.channel = self.channel_id
        new.dlc = len(data)
        new.data = bytearray(data)
        new.is_fd = False
        new.is_rx = True
        new.bitrate_switch = False
        new.error_state_indicator = False
        # ``_deliver(new, new)`` written out (the sender's frame is the delivered one), with
        # ``_push`` inlined for the other buses: same taps, same buses, same order.
        ch.frames += 1
        for tap in ch.taps:
            tap(new)
        for bus in ch.buses:
            if bus is self:
                if self.receive_own_messages:
                    copy = _copy(new, new.timestamp, self.channel_id, False)
                    if bus._filters is None or bus._matches_filters(copy):
                        bus._push(copy)
                continue
            if bus._filters is None or bus._matches_filters(new):
                q = bus._queue
                if q.maxlen is not None and len(q) == q.maxlen:
                    bus.rx_dropped += 1
                q.append(new)

    def _deliver(self, msg: Message, delivered: Message) -> None:
        """Hand ``delivered`` (stamped, ``is_rx``) to the taps and every other bus."""
        ch = self._ch
        stamp = delivered.timestamp
        name = self.channel_id
        ch.frames += 1
        for tap in ch.taps:
            tap(delivered)
        for bus in ch.buses:
            if bus is self:
                if not self.receive_own_messages:
                    continue
                copy = _copy(msg, stamp, name, False)
                if bus._filters is None or bus._matches_filters(copy):
                    bus._push(copy)
                continue
            if bus._filters is None or bus._matches_filters(delivered):
                bus._push(delivered)

    def _push(self, msg: Message) -> None:
        q = self._queue
        if q.maxlen is not None and len(q) == q.maxlen:
            self.rx_dropped += 1
        q.append(msg)

    def recv(self, timeout: float | None = None) -> Message | None:
        """The oldest pending frame, or None. ``timeout=0`` never blocks."""
        if not self._open:
            raise CanOperationError("Cannot operate on a closed bus")
        q = self._queue
        if q:
            return q.popleft()
        if timeout is not None and timeout <= 0:
            return None
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            time.sleep(_POLL_S)
            if q:
                return q.popleft()
            if not self._open:
                raise CanOperationError("Cannot operate on a closed bus")
            if deadline is not None and time.monotonic() >= deadline:
                return None

    def _recv_internal(self, timeout: float | None) -> tuple[Message | None, bool]:
        msg = self.recv(timeout)
        return msg, True  # filters were applied at delivery

    @property
    def pending(self) -> int:
        """Frames waiting in this bus's receive queue."""
        return len(self._queue)

    def flush_tx_buffer(self) -> None:
        """Nothing is buffered on the transmit side (delivery is immediate)."""

    def shutdown(self) -> None:
        super().shutdown()
        if self._open:
            self._open = False
            with _lock:
                ch = self._ch
                if self in ch.buses:
                    ch.buses.remove(self)
                if not ch.buses and not ch.taps and _channels.get(ch.name) is ch:
                    del _channels[ch.name]
