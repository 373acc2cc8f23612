"""The Neuron CAN bus of the lockstep stack without python-can between the Rust CAN master and
the Rust Neuron bank (``rdm._rdm.CanWire``, docs/canbus.md).

A :class:`CanWireLink` takes the place of both python-can buses on an in-process channel: the
master (:class:`rdm.nodes.can_master.CanMaster`) and the bank
(:class:`rdm.nodes.neuron_bank.NeuronBankNode`) are given the link instead of a bus, and
frames go from one Rust core to the other at the same ticks, in the same order and with the
same channel-clock stamps as on the in-process channel. :class:`WireCandump` writes the same
``candump -L`` lines as :class:`rdm.sim.CandumpCapture` would.

Only for a channel with no other endpoint: the link holds one guard bus on the channel (so
the name stays taken and the channel clock is shared), and every master tick checks that no
other bus or tap has joined; if one has, :class:`CanWireError` is raised (build the stack
with ``StackOptions.can_wire=False`` to share the channel with python-can endpoints).
"""

from __future__ import annotations

import os

from rdm import _rdm
from rdm.link.inproc_can import InProcessBus
from rdm.output_files import open_output

#: Log frames kept in the core before they are formatted and written.
DRAIN_AT = 8192


class CanWireError(RuntimeError):
    """A python-can endpoint joined a channel the wire serves alone."""


class CanWireLink:
    """The wire of channel ``channel`` (an in-process channel name)."""

    def __init__(self, channel: str, *, logging: bool = True) -> None:
        self.channel = channel
        self.wire = _rdm.CanWire(logging=logging)
        self._guard = InProcessBus(channel)
        self._ch = self._guard._ch
        self.capture: WireCandump | None = None
        self._open = True

    def clock(self) -> float:
        """The channel clock (what the in-process bus stamps frames with)."""
        return self._ch.clock()

    def check_alone(self) -> None:
        """Raise :class:`CanWireError` if another python-can endpoint or tap is on the channel."""
        ch = self._ch
        if len(ch.buses) != 1 or ch.taps:
            raise CanWireError(
                f"CanWire: channel {self.channel!r} has {len(ch.buses) - 1} other bus(es) and "
                f"{len(ch.taps)} tap(s); the wire only serves a channel without other "
                "endpoints (StackOptions.can_wire=False shares it with python-can)"
            )

    def drain(self) -> None:
        """Hand the logged frames to the capture (if any)."""
        if self.capture is not None:
            self.capture.write_pending()

    def shutdown(self) -> None:
        """Write what is logged and release the channel (idempotent; both nodes call it)."""
        if self._open:
            self._open = False
            if self.capture is not None:
                self.capture.close()
            self._guard.shutdown()


class WireCandump:
    """``candump -L`` capture of a :class:`CanWireLink` (same bytes as ``CandumpCapture`` on
    the in-process channel): the core formats the lines, this writes them."""

    def __init__(self, path: str | os.PathLike[str], link: CanWireLink) -> None:
        if not str(path).endswith(".log"):
            raise ValueError(f"WireCandump: {path!r} must end in .log")
        self.path = path
        self._link = link
        self._file = open_output(path, "w")  # closed in close()
        link.capture = self

    @property
    def frames(self) -> int:
        """Frames captured so far."""
        return self._link.wire.frames

    def write_pending(self) -> None:
        if not self._file.closed:
            self._file.write(self._link.wire.drain_log(self._link.channel))

    def flush(self) -> None:
        self.write_pending()
        if not self._file.closed:
            self._file.flush()

    def close(self) -> None:
        """Write the rest and close the file (idempotent)."""
        if not self._file.closed:
            self.write_pending()
            self._file.close()
