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


class CandumpCapture:
    """Write every frame of ``channel`` (an ``inproc:`` channel name, or None) to ``path``."""

    def __init__(self, path: str | os.PathLike[str], channel: str | None = None) -> None:
        if not str(path).endswith(".log"):
            raise ValueError(f"CandumpCapture: {path!r} must end in .log")
        self.path = path
        self._writer = can.CanutilsLogWriter(path, channel=channel or "can0")
        self.frames = 0
        self._channel = channel
        if channel is not None:
            inproc_can.add_tap(channel, self.on_message_received)

    def on_message_received(self, msg: can.Message) -> None:
        """Append one frame."""
        self._writer.on_message_received(msg)
        self.frames += 1

    def close(self) -> None:
        """Detach from the channel and close the file (idempotent)."""
        if self._channel is not None:
            inproc_can.remove_tap(self._channel, self.on_message_received)
            self._channel = None
        if not self._writer.file.closed:
            self._writer.stop()
