"""UART byte transport over pyserial, chosen by one configuration string per port.

Accepted specs (the Spinal link runs at 921600 baud 8N1 without flow control, fact sheet
sec. 1.1, which is the default):

* ``serial:/dev/ttyUSB0@921600`` or ``serial:/dev/flight_controller`` (default baud), also a
  bare ``/dev/ttyUSB0[@baud]``;
* a pyserial URL such as ``loop://`` (echo), ``socket://host:port`` or ``rfc2217://host:port``;
* ``pty``: a fresh pseudo-terminal pair; the returned link is pyserial on the slave side and its
  :attr:`SerialLink.peer` is pyserial on the master side (for tests and simulators).

Reads never block: :meth:`SerialLink.read_available` returns what has arrived (maybe ``b""``).
A pty ignores the baud rate and delivers at memory speed; line timing must be modelled elsewhere.

A device port (``serial:/dev/...``) survives an unplug: the first read or write that fails
(EIO once the USB adapter is gone) closes it, counts it in :attr:`SerialLink.errors`, and the
link then tries to open the same path again every :attr:`SerialLink.reopen_s` (0.5 s) on its
reads, counting each success in :attr:`SerialLink.reopens`. Meanwhile reads give ``b""`` and
writes hand over nothing. A udev name such as ``/dev/flight_controller`` follows the adapter to
its new ``ttyUSB``/``ttyACM`` node. Other links raise the ``OSError`` to their caller.

Writes block by default (pyserial's ``write`` waits until the kernel took every byte). A
real-time loop calls :meth:`SerialLink.nonblocking_writes`: from then on :meth:`SerialLink.write`
never waits. Each write's bytes join a bounded backlog whole, or are dropped whole when the
backlog would exceed its limit (counted in :attr:`SerialLink.dropped_writes` and
:attr:`SerialLink.dropped_bytes`); the backlog goes to the port with non-blocking
``os.write`` calls on each write and each read, so a frame is never cut and a reader that
stops reading costs dropped writes, not the loop's time.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import re
import time
from dataclasses import dataclass

import serial

DEFAULT_BAUD = 921600
_URL = re.compile(r"^[a-z][a-z0-9+]*://", re.IGNORECASE)


class SerialSpecError(ValueError):
    """A configuration string that is not a serial spec; the message lists the accepted forms."""


@dataclass(frozen=True)
class SerialSpec:
    """A parsed spec: ``kind`` is ``device``, ``url`` or ``pty``."""

    kind: str
    target: str
    baudrate: int


_FORMS = "'serial:/dev/ttyUSB0@921600', '/dev/ttyUSB0', 'loop://', 'socket://host:port' or 'pty'"


def parse_serial_spec(spec: str) -> SerialSpec:
    """Parse a configuration string (see the module doc) without opening anything."""
    if not isinstance(spec, str) or not spec.strip():
        raise SerialSpecError(f"empty serial spec; expected {_FORMS}")
    text = spec.strip()
    if text == "pty":
        return SerialSpec("pty", "", DEFAULT_BAUD)
    if _URL.match(text):
        return SerialSpec("url", text, DEFAULT_BAUD)
    if text.startswith("serial:"):
        text = text[len("serial:") :]
    elif not text.startswith("/"):
        raise SerialSpecError(f"unrecognised serial spec {spec!r}; expected {_FORMS}")
    path, sep, baud_text = text.rpartition("@") if "@" in text else (text, "", "")
    if not path:
        raise SerialSpecError(f"serial spec {spec!r} has no device path; expected {_FORMS}")
    baud = DEFAULT_BAUD
    if sep:
        if not baud_text.isdigit() or int(baud_text) <= 0:
            raise SerialSpecError(
                f"serial spec {spec!r}: baud rate {baud_text!r} is not a positive integer"
            )
        baud = int(baud_text)
    return SerialSpec("device", path, baud)


class SerialLink:
    """A non-blocking byte pipe over one pyserial port."""

    #: Seconds between attempts to open a lost device port again.
    reopen_s = 0.5

    def __init__(
        self,
        port: serial.SerialBase,
        spec: str,
        peer: SerialLink | None = None,
        device: SerialSpec | None = None,
    ) -> None:
        self.port = port
        self.spec = spec
        self.peer = peer  # the other end of a pty pair, else None
        #: the device this link opens again after an unplug (None: errors are raised)
        self.device = device
        self.errors = 0
        self.reopens = 0
        self._lost_at: float | None = None
        self._closed = False
        #: bytes the port has not taken yet (non-blocking writes only) and their limit
        self.backlog = bytearray()
        self.backlog_limit: int | None = None
        self.dropped_writes = 0
        self.dropped_bytes = 0

    def nonblocking_writes(self, backlog_limit: int = 16384) -> None:
        """Make :meth:`write` non-blocking with a backlog of at most ``backlog_limit``
        bytes (see the module doc). ValueError for a port without a file descriptor (a
        ``socket://``/``loop://`` URL) or a limit < 1."""
        if not isinstance(backlog_limit, int) or backlog_limit < 1:
            raise ValueError(f"backlog_limit={backlog_limit!r} must be an integer >= 1")
        if not isinstance(getattr(self.port, "fd", None), int):
            raise ValueError(f"{self.spec}: non-blocking writes need a port with a descriptor")
        self.backlog_limit = backlog_limit

    def _flush_backlog(self) -> None:
        """Hand the port what it takes of the backlog now, without waiting."""
        if not self.backlog or self._lost_at is not None:
            return
        try:
            n = os.write(self.port.fd, self.backlog)
        except BlockingIOError:
            return
        except OSError as exc:
            self.dropped_bytes += len(self.backlog)
            self.backlog.clear()
            self._lose(exc)
            return
        del self.backlog[:n]

    @property
    def connected(self) -> bool:
        """False while a lost device port waits to be opened again."""
        return self._lost_at is None

    def _lose(self, exc: OSError) -> None:
        """A failed read or write: raise it, or (a device) close the port and retry later."""
        self.errors += 1
        if self.device is None:
            raise exc
        self._lost_at = time.monotonic()
        with contextlib.suppress(OSError):
            self.port.close()

    def _reopen(self) -> bool:
        assert self.device is not None and self._lost_at is not None
        now = time.monotonic()
        if self._closed or now - self._lost_at < self.reopen_s:
            return False
        self._lost_at = now
        try:
            self.port = _open_port(self.device.target, self.device.baudrate, url=False)
        except (OSError, ValueError):
            return False
        self._lost_at = None
        self.reopens += 1
        return True

    def read_available(self) -> bytes:
        """All bytes received so far (``b""`` if none); never blocks."""
        if self._lost_at is not None and not self._reopen():
            return b""
        if self.backlog:
            self._flush_backlog()
        try:
            waiting = self.port.in_waiting
            return self.port.read(waiting) if waiting else b""
        except OSError as exc:  # serial.SerialException is an OSError
            self._lose(exc)
            return b""

    def write(self, data: bytes) -> int:
        """Write ``data``; returns the number of bytes handed to the port (with
        :meth:`nonblocking_writes`: taken into the backlog, 0 when dropped)."""
        if not data or self._lost_at is not None:
            return 0
        limit = self.backlog_limit
        if limit is not None:
            if len(self.backlog) + len(data) > limit:
                self.dropped_writes += 1
                self.dropped_bytes += len(data)
                self._flush_backlog()
                return 0
            self.backlog += data
            self._flush_backlog()
            return len(data)
        try:
            written = self.port.write(data)
        except OSError as exc:
            self._lose(exc)
            return 0
        return len(data) if written is None else int(written)

    def close(self) -> None:
        """Close this end (and the peer of a pty pair)."""
        self._closed = True
        self.port.close()
        if self.peer is not None:
            peer, self.peer = self.peer, None
            peer.close()

    def __enter__(self) -> SerialLink:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class _PtyMasterSerial(serial.Serial):
    """pyserial on an already-open pty master fd (the master has no path to open by name)."""

    def __init__(self, master_fd: int, name: str) -> None:
        self._master_fd = master_fd
        super().__init__(port=None, baudrate=DEFAULT_BAUD, timeout=0)
        self._port = name

    def open(self) -> None:
        self.fd = self._master_fd
        self.pipe_abort_read_r, self.pipe_abort_read_w = os.pipe()
        self.pipe_abort_write_r, self.pipe_abort_write_w = os.pipe()
        fcntl.fcntl(self.pipe_abort_read_r, fcntl.F_SETFL, os.O_NONBLOCK)
        fcntl.fcntl(self.pipe_abort_write_r, fcntl.F_SETFL, os.O_NONBLOCK)
        fcntl.fcntl(self.fd, fcntl.F_SETFL, os.O_NONBLOCK)
        self.is_open = True


def _open_port(target: str, baudrate: int, url: bool) -> serial.SerialBase:
    kwargs = dict(
        baudrate=baudrate,
        bytesize=serial.EIGHTBITS,
        parity=serial.PARITY_NONE,
        stopbits=serial.STOPBITS_ONE,
        xonxoff=False,
        rtscts=False,
        dsrdtr=False,
        timeout=0,
    )
    if url:
        return serial.serial_for_url(target, **kwargs)
    return serial.Serial(target, **kwargs)


def open_pty_pair() -> tuple[SerialLink, SerialLink]:
    """A pseudo-terminal pair as two links: (slave side, master side), both pyserial."""
    master, slave = os.openpty()
    slave_name = os.ttyname(slave)
    try:
        slave_port = _open_port(slave_name, DEFAULT_BAUD, url=False)  # configures raw 8N1
    finally:
        os.close(slave)  # pyserial holds its own fd on the slave
    master_port = _PtyMasterSerial(master, f"{slave_name} (master)")
    master_port.open()
    master_link = SerialLink(master_port, "pty-master")
    return SerialLink(slave_port, "pty", master_link), master_link


def open_serial(spec: str) -> SerialLink:
    """Open the port a configuration string names (see the module doc)."""
    parsed = parse_serial_spec(spec)
    if parsed.kind == "pty":
        slave, _master = open_pty_pair()
        return slave
    try:
        port = _open_port(parsed.target, parsed.baudrate, url=parsed.kind == "url")
    except ValueError as exc:  # pyserial rejects unknown URL schemes and bad settings this way
        raise SerialSpecError(f"serial spec {spec!r}: {exc}") from exc
    return SerialLink(port, spec, device=parsed if parsed.kind == "device" else None)
