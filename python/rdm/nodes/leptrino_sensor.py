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

from rdm._rdm import LeptrinoStreamCore
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
        #: The stream state (wrench, streaming, temperature, sensor number, sample frame,
        #: counters), shared with the lockstep kernel's streaming tick; it refuses a
        #: temperature outside int16 and a sensor number outside 0..254 (ValueError).
        self._stream = LeptrinoStreamCore(
            tuple(float(v) for v in sensor_model.rated), temperature, sensor_no
        )
        self.uart = uart
        self.model = sensor_model
        self.name = name
        self.period = 1.0 / rate_hz
        self.rate_hz = rate_hz
        self.info = lp.ProductInfo(
            sensor_model.name[: lp.PRODUCT_NAME_SIZE],
            serial_number,
            firmware_version,
            f"{rate_hz:g}"[: lp.OUTPUT_RATE_SIZE],
            term_no=sensor_no,
        )
        self.digital_filter = 0
        self.parser = lp.LeptrinoStreamParser()
        self.commands: Counter[str] = Counter()
        #: Host-side errors (framing, commands); :attr:`errors` adds the stream's.
        self._errors: Counter[str] = Counter()

    # ------------------------------------------------------------------ state
    @property
    def streaming(self) -> bool:
        """Whether the sensor streams (DATA_START / DATA_STOP)."""
        return self._stream.streaming

    @streaming.setter
    def streaming(self, on: bool) -> None:
        self._stream.streaming = bool(on)

    @property
    def temperature(self) -> int:
        """Temperature every later frame carries (raw int16); ValueError outside int16."""
        return self._stream.temperature

    @temperature.setter
    def temperature(self, value: int) -> None:
        self._stream.temperature = value

    @property
    def sensor_no(self) -> int:
        """The sensor number (0..254) it answers to and its frames carry."""
        return self._stream.sensor_no

    @sensor_no.setter
    def sensor_no(self, value: int) -> None:
        self._stream.sensor_no = value

    @property
    def wrench(self) -> tuple[float, ...]:
        """The wrench the sensor measures now (Fx, Fy, Fz, Mx, My, Mz; after the clip)."""
        return tuple(self._stream.wrench)

    @property
    def limits(self) -> tuple[float, ...]:
        """Highest magnitude per axis the int16 counts can say (``32767 * rated / 10000``)."""
        return tuple(self._stream.limits)

    @property
    def frames_sent(self) -> int:
        """Frames the UART took whole (samples and responses)."""
        return self._stream.frames_sent

    @property
    def bytes_dropped(self) -> int:
        """Bytes the UART did not take."""
        return self._stream.bytes_dropped

    @property
    def saturated_samples(self) -> int:
        """Wrench samples clipped to the limits."""
        return self._stream.saturated_samples

    @property
    def errors(self) -> Counter[str]:
        """Errors by kind (a Counter built at each read): framing and command errors of the host's
        bytes, ``bad_wrench`` (refused samples), ``tx_short`` (writes cut short)."""
        out = Counter(self._errors)
        s = self._stream
        if s.bad_wrench:
            out["bad_wrench"] = s.bad_wrench
        if s.tx_short:
            out["tx_short"] = s.tx_short
        return out

    # ------------------------------------------------------------------ inputs
    def set_wrench(self, force: Sequence[float], torque: Sequence[float]) -> None:
        """The wrench the sensor measures now (N, N m, sensor frame): clipped to
        :attr:`limits` (counted in :attr:`saturated_samples`); not finite, or not six values
        in all, refused (``errors["bad_wrench"]``, the previous wrench stays)."""
        f = force.tolist() if hasattr(force, "tolist") else force
        t = torque.tolist() if hasattr(torque, "tolist") else torque
        self._stream.set_wrench((*f, *t))

    def set_wrench_values(self, w: Sequence[float]) -> None:
        """:meth:`set_wrench` of one (Fx, Fy, Fz, Mx, My, Mz) sequence (the plant bridge's
        path: ``Plant.wrench_values`` gives it, no arrays in between)."""
        self._stream.set_wrench(w)

    # ------------------------------------------------------------------ node
    def tick(self, now: float) -> None:
        """Answer the host's commands, then stream one sample if streaming."""
        data = self.uart.read_available()
        if data:
            for event in self.parser.feed(data):
                if event.error is not None:
                    self._errors[f"framing_{event.error.reason}"] += 1
                    continue
                self._command(event.payload or b"")
        if self._stream.streaming:
            self._write(self._stream.sample_frame())

    def _command(self, payload: bytes) -> None:
        try:
            cmd = lp.parse_command(payload)
        except lp.LeptrinoError as exc:
            self._errors[f"command_{exc.reason}"] += 1
            if len(payload) >= lp.HEADER_LEN:
                undefined = exc.reason == "command"
                result = lp.Result.UNDEFINED_COMMAND if undefined else lp.Result.LENGTH_ERROR
                self._write(lp.encode_response(lp.Ack(payload[2], result, self.sensor_no)))
            return
        if cmd.sensor_no not in (lp.BROADCAST_SENSOR_NO, self.sensor_no):
            self._errors["not_addressed"] += 1
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
        self._stream.count_write(len(frame), n)

    def close(self) -> None:
        """Close the UART (the node owns it)."""
        self.uart.close()
