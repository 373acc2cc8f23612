"""Leptrino force/torque sensor mirror: the sensor end of its serial link (fact sheet sec. 5).

Each ``tick(now)``:

1. reads the host's bytes from the UART, de-frames them (``DLE STX ... DLE ETX BCC``) and answers
   every command as the sensor would: GET_INF (product info), GET_LIMIT (rated values),
   DATA_START (starts the stream; the data frames themselves carry command 0x32), DATA_STOP (ack),
   SET_DF (ack, value kept), GET_DF (the value). A command addressed to another sensor number is
   ignored; an unknown command or a bad length is answered with the matching result code;
   framing errors are counted;
2. while streaming, sends one data frame with the latest wrench (set by the plant bridge through
   :meth:`set_wrench`) as raw int16 counts (``round(value * 10000 / rated)``).

One frame per tick: the stream rate is ``rate_hz`` (the node's period is ``1 / rate_hz``; in
lockstep it must be a whole number of milliseconds, so 1.2 kHz is not available, 1 kHz is).
The node never blocks: a write the port cannot take is cut short and the lost bytes counted.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Sequence
from typing import ClassVar

from rdm._rdm import leptrino_force_frame
from rdm.link.tapped_link import TappedLink
from rdm.link.uart_pipe import InProcessUartEnd
from rdm.protocol import leptrino as lp


class LeptrinoSensorNode:
    """A Leptrino sensor (``sensor_model``: e.g. ``"CFS034CA301U"``) streaming at ``rate_hz``.

    ``uart`` is any byte link with ``read_available() -> bytes`` and ``write(bytes) -> int``
    (a :class:`rdm.link.serial.SerialLink` pty end, or a capture wrapper around one).
    """

    #: Its part of the lockstep kernel (``rdm.nodes.lockstep_kernel.kind_of``); read from
    #: this class itself, so a subclass has only its Python tick unless it sets its own.
    lockstep_part: ClassVar[str] = "leptrino"

    def __init__(
        self,
        uart,
        sensor_model: str | lp.SensorModel = "CFS034CA301U",
        rate_hz: float = 1000.0,
        *,
        name: str = "leptrino_foot",
        sensor_no: int = 0,
        serial_number: str = "SIM00001",
        firmware_version: str = "1.00",
        temperature: int = 250,
    ) -> None:
        if not (math.isfinite(rate_hz) and rate_hz > 0):
            raise ValueError(f"LeptrinoSensorNode: rate_hz {rate_hz!r} must be > 0")
        if isinstance(sensor_model, str):
            if sensor_model not in lp.MODELS:
                raise ValueError(
                    f"LeptrinoSensorNode: unknown sensor_model {sensor_model!r} "
                    f"(known: {sorted(lp.MODELS)})"
                )
            sensor_model = lp.MODELS[sensor_model]
        if not 0 <= sensor_no <= 0xFE:
            raise ValueError(f"LeptrinoSensorNode: sensor_no {sensor_no!r} not in 0..254")
        self.uart = uart
        self.model = sensor_model
        self.name = name
        self.period = 1.0 / rate_hz
        self.rate_hz = rate_hz
        self.sensor_no = sensor_no
        self.info = lp.ProductInfo(
            sensor_model.name[: lp.PRODUCT_NAME_SIZE],
            serial_number,
            firmware_version,
            f"{rate_hz:g}"[: lp.OUTPUT_RATE_SIZE],
            term_no=sensor_no,
        )
        self.temperature = temperature
        self.digital_filter = 0
        self.streaming = False
        self.parser = lp.LeptrinoStreamParser()
        # Highest raw count the sensor outputs: the int16 range.
        self._limits = tuple(0x7FFF * k / lp.RAW_AT_RATED for k in sensor_model.rated)
        self._wrench: tuple[float, ...] = (0.0,) * 6
        #: (wrench tuple, temperature, sensor_no, frame) of the last sample frame sent
        self._frame_cache: tuple | None = None
        self.commands: Counter[str] = Counter()
        self.errors: Counter[str] = Counter()
        self.frames_sent = 0
        self.bytes_dropped = 0
        self.saturated_samples = 0

    # ------------------------------------------------------------------ inputs
    def set_wrench(self, force: Sequence[float], torque: Sequence[float]) -> None:
        """The wrench the sensor measures now (N, N m, sensor frame). Non-finite is refused."""
        # Plain floats (numpy arrays -> tolist): the same values, cheaper arithmetic below.
        f = force.tolist() if hasattr(force, "tolist") else force
        t = torque.tolist() if hasattr(torque, "tolist") else torque
        self.set_wrench_values((*f, *t))

    def set_wrench_values(self, w: tuple[float, ...]) -> None:
        """:meth:`set_wrench` of one (Fx, Fy, Fz, Mx, My, Mz) tuple (the plant bridge's
        1 kHz path: ``Plant.wrench_values`` gives it, no arrays in between)."""
        if type(w) is not tuple:
            w = tuple(w)
        if len(w) == 6:
            # The common sample: six values inside the limits (NaN and inf fail a chained
            # comparison), which the clip below leaves as they are: keep ``w`` itself.
            lim = self._limits
            if (
                -lim[0] <= w[0] <= lim[0]
                and -lim[1] <= w[1] <= lim[1]
                and -lim[2] <= w[2] <= lim[2]
                and -lim[3] <= w[3] <= lim[3]
                and -lim[4] <= w[4] <= lim[4]
                and -lim[5] <= w[5] <= lim[5]
            ):
                self._wrench = w
                return
        if len(w) != 6 or not all(math.isfinite(v) for v in w):
            self.errors["bad_wrench"] += 1
            return
        clipped = tuple(max(-m, min(m, v)) for v, m in zip(w, self._limits, strict=True))
        if clipped != w:
            self.saturated_samples += 1
        self._wrench = clipped

    # ------------------------------------------------------------------ node
    def tick(self, now: float) -> None:
        """Answer the host's commands, then stream one sample if streaming."""
        data = self.uart.read_available()
        if data:
            for event in self.parser.feed(data):
                if event.error is not None:
                    self.errors[f"framing_{event.error.reason}"] += 1
                    continue
                self._command(event.payload or b"")
        if self.streaming:
            self._write(self._sample_frame())

    def _sample_frame(self) -> bytes:
        """The data frame of the latest wrench, encoded in Rust (``leptrino_force_frame``) and
        reused while the wrench (the same tuple: a new one per ``set_wrench``), temperature
        and sensor number are unchanged. A temperature outside int16 or a sensor number
        outside 0..254 raises ValueError."""
        w = self._wrench
        temp = self.temperature
        no = self.sensor_no
        cache = self._frame_cache
        if cache is not None and cache[0] is w and cache[1] == temp and cache[2] == no:
            return cache[3]
        frame = None
        if type(temp) is int and type(no) is int and -0x8000 <= temp <= 0x7FFF:
            frame = leptrino_force_frame(w, self.model.rated, temp, 0, no, 0)
        if frame is None:
            raise ValueError(
                f"LeptrinoSensorNode: temperature {temp!r} must be an int in -32768..32767 "
                f"and sensor_no {no!r} an int in 0..254"
            )
        self._frame_cache = (w, temp, no, frame)
        return frame

    def _command(self, payload: bytes) -> None:
        try:
            cmd = lp.parse_command(payload)
        except lp.LeptrinoError as exc:
            self.errors[f"command_{exc.reason}"] += 1
            if len(payload) >= lp.HEADER_LEN:
                undefined = exc.reason == "command"
                result = lp.Result.UNDEFINED_COMMAND if undefined else lp.Result.LENGTH_ERROR
                self._write(lp.encode_response(lp.Ack(payload[2], result, self.sensor_no)))
            return
        if cmd.sensor_no not in (lp.BROADCAST_SENSOR_NO, self.sensor_no):
            self.errors["not_addressed"] += 1
            return
        self.commands[cmd.command.name] += 1
        c = lp.Command
        if cmd.command == c.GET_INF:
            resp: lp.Response = self.info
        elif cmd.command == c.GET_LIMIT:
            resp = lp.RatedValues(tuple(self.model.rated), term_no=self.sensor_no)
        elif cmd.command == c.DATA_START:
            self.streaming = True
            return
        elif cmd.command == c.DATA_STOP:
            self.streaming = False
            resp = lp.Ack(c.DATA_STOP, lp.Result.OK, self.sensor_no)
        elif cmd.command == c.SET_DF:
            self.digital_filter = int(cmd.digital_filter or 0)
            resp = lp.Ack(c.SET_DF, lp.Result.OK, self.sensor_no)
        else:  # GET_DF
            resp = lp.DigitalFilter(self.digital_filter, term_no=self.sensor_no)
        self._write(lp.encode_response(resp))

    def _write(self, frame: bytes) -> None:
        try:
            n = self.uart.write(frame)
        except OSError:
            n = 0
        if n < len(frame):
            self.bytes_dropped += len(frame) - n
            self.errors["tx_short"] += 1
        else:
            self.frames_sent += 1

    # ------------------------------------------------------------ lockstep kernel
    def kernel_plan(self) -> tuple | None:
        """What ``rdm._rdm.LockstepKernel`` needs to run :meth:`tick` in Rust while no host
        command is waiting: (streaming, limits, rated, temperature, sensor number, wrench,
        the cached frame of that wrench or None), or None when the tick has
        no Rust form now (bytes from the host, a UART other than an open in-process pipe
        whose writes are whole, a temperature or sensor number the Rust encoder does not
        take) (docs/sim.md)."""
        uart = self.uart
        if type(uart) is not TappedLink or type(uart.link) is not InProcessUartEnd:
            return None
        end = uart.link
        if end.inbox or end.closed or end.peer is None or end.peer.closed:
            return None
        temp, no = self.temperature, self.sensor_no
        if type(temp) is not int or type(no) is not int or not -0x8000 <= temp <= 0x7FFF:
            return None
        w = self._wrench
        cache = self._frame_cache
        frame = None
        if cache is not None and cache[0] is w and cache[1] == temp and cache[2] == no:
            frame = cache[3]
        rated = tuple(float(v) for v in self.model.rated)
        return (self.streaming, self._limits, rated, temp, no, w, frame)

    def kernel_commit(
        self,
        data: bytes,
        frames: int,
        wrench: tuple[float, ...],
        frame: bytes | None,
        marks: Sequence[tuple[float, int]] = (),
    ) -> None:
        """The sample frames of the kernel's ticks (written now, in one write: the bytes the
        ticks would have written one by one; ``marks`` each frame's ``(tick time s, end)`` in
        ``data`` for the capture's time index), the wrench last set and its frame."""
        if data:
            try:
                n = self.uart.write_marked(data, marks)
            except OSError:
                n = 0
            if n < len(data):  # not on an open in-process pipe (kernel_plan's condition)
                self.bytes_dropped += len(data) - n
                self.errors["tx_short"] += 1
            else:
                self.frames_sent += frames
        self._wrench = wrench
        if frame is not None:
            self._frame_cache = (wrench, self.temperature, self.sensor_no, frame)

    def close(self) -> None:
        """Close the UART (the node owns it)."""
        self.uart.close()
