"""candump ``.log`` capture of a CAN bus (``candump -L`` format, python-can's writer).

On an in-process channel the capture is a tap: it sees every frame at send time, stamped with the
simulated clock, so two runs with the same seed write identical files. On any other bus use
:meth:`CandumpCapture.on_message_received` from a ``can.Notifier`` or a draining node.
``rdm decode can.log`` and ``rdm.protocol.neuron.decode_candump`` read the result.
"""

from __future__ import annotations

import os

import can

from rdm.link import inproc_can
from rdm.output_files import open_output

#: Frames buffered before one write to the file.
BATCH_LINES = 512
#: Line tails (channel, id, data, direction) remembered; the memo is cleared when full.
REST_CACHE_SIZE = 4096


class CandumpCapture:
    """Write every frame of ``channel`` (an ``inproc:`` channel name, or None) to ``path``."""

    def __init__(self, path: str | os.PathLike[str], channel: str | None = None) -> None:
        if not str(path).endswith(".log"):
            raise ValueError(f"CandumpCapture: {path!r} must end in .log")
        self.path = path
        # the writer takes an open file: ours, opened without following a symbolic link
        self._writer = can.CanutilsLogWriter(open_output(path, "w"), channel=channel or "can0")
        self.frames = 0
        self._lines: list[str] = []
        self._stamp: float | None = None  # the float object _stamp_text was made from
        self._stamp_text = ""
        self._rest: dict[tuple, str] = {}
        self._channel = channel
        if channel is not None:
            inproc_can.add_tap(channel, self.on_message_received)

    def on_message_received(self, msg: can.Message) -> None:
        """Append one frame (the line python-can's ``CanutilsLogWriter`` writes)."""
        w = self._writer
        stamp = msg.timestamp
        channel = msg.channel
        # (python-can's writer keeps the FIRST frame's timestamp as its floor.)
        if (
            w.last_timestamp is not None
            and stamp is not None
            and stamp >= w.last_timestamp
            and isinstance(channel, str)
            and not channel.isdigit()
            and not (msg.is_error_frame or msg.is_extended_id or msg.is_remote_frame or msg.is_fd)
        ):
            # The common frame (classic, standard id, in time order): the writer's own
            # format, without its per-frame branching (same bytes; checked in the tests).
            # The stamp text is reused for the frames of one tick (the same float object from
            # the channel clock), the rest of the line per (channel, id, data, direction).
            if stamp is not self._stamp:
                self._stamp = stamp
                self._stamp_text = f"({stamp:f}) "
            key = (msg.arbitration_id, bytes(msg.data), channel, msg.is_rx)
            rest = self._rest.get(key)
            if rest is None:
                if len(self._rest) >= REST_CACHE_SIZE:
                    self._rest.clear()
                rest = self._rest[key] = (
                    f"{channel} {msg.arbitration_id:03X}#{msg.data.hex().upper()}"
                    + (" R\n" if msg.is_rx else " T\n")
                )
            lines = self._lines
            lines.append(self._stamp_text + rest)
            if len(lines) >= BATCH_LINES:
                self.flush()
        else:
            self.flush()
            w.on_message_received(msg)
        self.frames += 1

    def flush(self) -> None:
        """Write the lines batched so far (one write call instead of one per frame)."""
        if self._lines:
            self._writer.file.write("".join(self._lines))
            self._lines.clear()

    def close(self) -> None:
        """Detach from the channel and close the file (idempotent)."""
        if self._channel is not None:
            inproc_can.remove_tap(self._channel, self.on_message_received)
            self._channel = None
        if not self._writer.file.closed:
            self.flush()
            self._writer.stop()
