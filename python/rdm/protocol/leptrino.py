"""Leptrino 6-axis force/torque sensor serial protocol (fact sheet sec. 5), both roles.

Framing: ``DLE STX | payload with every 0x10 doubled | DLE ETX | BCC``; BCC is the XOR of the
unstuffed payload bytes and ETX, and is sent raw (never stuffed). Payload = 4-byte header
``[len, sensor/terminal no, command, reserved|result]`` + body, ``len`` counting the whole
unstuffed payload. USB CDC serial at 460800 baud 8N1.

Host role: :func:`encode_command` / helpers, :class:`LeptrinoStreamParser`,
:func:`parse_response`. Sensor role (for a sensor mirror): :func:`parse_command` and
:func:`encode_response`. Conversion: raw 10000 = rated value (:func:`to_wrench`).
"""

from __future__ import annotations

import enum
import math
import re
import struct
from collections import Counter
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

from rdm._rdm import leptrino_ok_sample_run as _ok_sample_run  # the Rust scan of OK samples

DLE, STX, ETX = 0x10, 0x02, 0x03
DLE_BYTE = bytes([DLE])
#: A whole frame from its DLE STX: stuffed payload (plain bytes or DLE DLE), DLE ETX, BCC.
_WHOLE_FRAME = re.compile(rb"\x10\x02((?:[^\x10]|\x10\x10)*)\x10\x03(.)", re.S)
#: Leptrino's receiver drops frames whose unstuffed payload exceeds this.
MAX_PAYLOAD = 255
HEADER_LEN = 4
BROADCAST_SENSOR_NO = 0xFF
RAW_AT_RATED = 10000
# Fixed-width ASCII fields of the GET_INF response (Leptrino ``pCommon.h``; see docs/canbus.md).
PRODUCT_NAME_SIZE, SERIAL_SIZE, FIRMWARE_VERSION_SIZE, OUTPUT_RATE_SIZE = 16, 8, 4, 6


class LeptrinoError(ValueError):
    """A bad Leptrino frame or value; ``reason`` is a short category used for counting."""

    def __init__(self, reason: str, message: str) -> None:
        super().__init__(f"{reason}: {message}")
        self.reason = reason


class Command(enum.IntEnum):
    GET_INF = 0x2A  # product info
    GET_LIMIT = 0x2B  # rated values
    DATA_START = 0x32  # start continuous output
    DATA_STOP = 0x33  # stop continuous output
    SET_DF = 0xA6  # set digital filter
    GET_DF = 0xB6  # get digital filter


class Result(enum.IntEnum):
    OK = 0x00
    LENGTH_ERROR = 0x01
    UNDEFINED_COMMAND = 0x02
    VALUE_ERROR = 0x03
    STATUS_ERROR = 0x04


# ------------------------------------------------------------------------------------ framing


def bcc(payload: bytes) -> int:
    """XOR of the unstuffed payload bytes and ETX."""
    out = ETX
    for b in payload:
        out ^= b
    return out


def stuff(payload: bytes) -> bytes:
    """Double every DLE byte."""
    return payload.replace(bytes([DLE]), bytes([DLE, DLE]))


def frame(payload: bytes) -> bytes:
    """``DLE STX stuffed(payload) DLE ETX BCC``."""
    if not 1 <= len(payload) <= MAX_PAYLOAD:
        raise LeptrinoError("length", f"payload length {len(payload)} not in 1..{MAX_PAYLOAD}")
    return bytes([DLE, STX]) + stuff(payload) + bytes([DLE, ETX, bcc(payload)])


@dataclass(frozen=True)
class StreamEvent:
    """One parser outcome: a good ``payload`` or an ``error``, at stream ``offset`` (of DLE)."""

    offset: int
    payload: bytes | None
    error: LeptrinoError | None = None


class _State(enum.Enum):
    IDLE = 0
    WAIT_STX = 1
    DATA = 2
    WAIT_ETX = 3
    WAIT_BCC = 4


@dataclass
class LeptrinoStreamParser:
    """Sans-IO byte-stream de-framer with resync; never raises on input bytes.

    Follows Leptrino's receiver: ``DLE STX`` inside a frame restarts it, ``DLE`` + anything
    but ``DLE``/``ETX``/``STX`` drops it, a BCC mismatch drops it. Counters: ``frames``,
    ``errors`` (by reason) and ``discarded_bytes`` (bytes outside any frame).
    """

    frames: int = 0
    errors: Counter = field(default_factory=Counter)
    discarded_bytes: int = 0
    _state: _State = _State.IDLE
    _buf: bytearray = field(default_factory=bytearray)
    _start: int = 0
    _pos: int = 0

    def _fail(self, reason: str, message: str) -> StreamEvent:
        self.errors[reason] += 1
        return StreamEvent(self._start, None, LeptrinoError(reason, message))

    def feed_ok_samples(
        self, data: bytes | bytearray
    ) -> tuple[int, bytes | None, list[StreamEvent]]:
        """:meth:`feed`, with the leading run of whole frames that each carry an OK sample
        (a payload :func:`is_ok_sample` accepts) summarised instead of returned one by one:
        ``(count, newest payload of the run or None, events of the rest of the chunk)``.
        Parser state and counters end as after :meth:`feed`; the run is scanned in Rust
        (``rdm._rdm.leptrino_ok_sample_run``) when the parser is idle, else count is 0."""
        data = bytes(data)
        if self._state is _State.IDLE:
            end, count, last_start, payload = _ok_sample_run(data)
            if count:
                # what feed's whole-frame path leaves behind after the run's last frame
                self.frames += count
                self._start = self._pos + last_start
                self._pos += end
                self._buf[:] = payload
                return count, payload, self.feed(data[end:]) if end < len(data) else []
        return 0, None, self.feed(data)

    def feed(self, data: bytes | bytearray) -> list[StreamEvent]:
        """Consume bytes; return the frames (and framing errors) completed by them."""
        events: list[StreamEvent] = []
        data = bytes(data)
        n = len(data)
        i = 0
        while i < n:
            if self._state is _State.IDLE and data[i] == DLE:
                # Fast path: a whole frame in this chunk, parsed at once; the same result as
                # the per-byte states below (anything else, e.g. DLE STX or a bad escape
                # inside, or an over-long payload, does not match and takes the byte path).
                m = _WHOLE_FRAME.match(data, i)
                if m is not None:
                    payload = m.group(1).replace(b"\x10\x10", DLE_BYTE)
                    if len(payload) <= MAX_PAYLOAD:
                        end = m.end()
                        self._start = self._pos
                        self._pos += end - i
                        i = end
                        self._buf[:] = payload
                        ch, want = data[end - 1], bcc(payload)
                        if ch != want:
                            events.append(
                                self._fail("bcc", f"BCC 0x{ch:02X} != computed 0x{want:02X}")
                            )
                        elif not payload:
                            events.append(self._fail("length", "empty payload"))
                        else:
                            self.frames += 1
                            events.append(StreamEvent(self._start, payload))
                        continue
            if self._state is _State.DATA:
                # Fast path: copy the plain bytes up to the next DLE in one slice (the same
                # result as appending them one at a time; an over-long payload still fails
                # at the byte that does not fit, through the per-byte path below).
                end = data.find(DLE_BYTE, i)
                if end < 0:
                    end = n
                take = min(end - i, MAX_PAYLOAD - len(self._buf))
                if take > 0:
                    self._buf += data[i : i + take]
                    self._pos += take
                    i += take
                    continue
            ch = data[i]
            i += 1
            pos = self._pos
            self._pos += 1
            st = self._state
            if st is _State.IDLE:
                if ch == DLE:
                    self._state, self._start = _State.WAIT_STX, pos
                else:
                    self.discarded_bytes += 1
            elif st is _State.WAIT_STX:
                if ch == STX:
                    self._state = _State.DATA
                    self._buf.clear()
                elif ch == DLE:  # DLE DLE STX: the second DLE may open the frame
                    self.discarded_bytes += 1
                    self._start = pos
                else:
                    self.discarded_bytes += 2
                    self._state = _State.IDLE
            elif st is _State.DATA:
                if ch == DLE:
                    self._state = _State.WAIT_ETX
                else:
                    self._append(ch, events)
            elif st is _State.WAIT_ETX:
                if ch == DLE:
                    self._state = _State.DATA
                    self._append(ch, events)
                elif ch == ETX:
                    self._state = _State.WAIT_BCC
                elif ch == STX:
                    events.append(self._fail("restart", "DLE STX inside a frame; frame dropped"))
                    self._start, self._state = pos - 1, _State.DATA
                    self._buf.clear()
                else:
                    events.append(self._fail("escape", f"DLE followed by 0x{ch:02X}"))
                    self._state = _State.IDLE
            else:  # WAIT_BCC
                self._state = _State.IDLE
                payload = bytes(self._buf)
                want = bcc(payload)
                if ch != want:
                    events.append(self._fail("bcc", f"BCC 0x{ch:02X} != computed 0x{want:02X}"))
                elif not payload:
                    events.append(self._fail("length", "empty payload"))
                else:
                    self.frames += 1
                    events.append(StreamEvent(self._start, payload))
        return events

    def _append(self, ch: int, events: list[StreamEvent]) -> None:
        if len(self._buf) >= MAX_PAYLOAD:
            events.append(self._fail("overflow", f"payload longer than {MAX_PAYLOAD} bytes"))
            self._state = _State.IDLE
            self._buf.clear()
            return
        self._buf.append(ch)

    @property
    def total_errors(self) -> int:
        return sum(self.errors.values())


# ----------------------------------------------------------------------------------- commands


@dataclass(frozen=True)
class CommandFrame:
    """Host -> sensor command. ``digital_filter`` only for SET_DF."""

    command: Command
    sensor_no: int = BROADCAST_SENSOR_NO
    digital_filter: int | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "command", Command(self.command))
        _check_u8("sensor_no", self.sensor_no)
        if (self.command == Command.SET_DF) != (self.digital_filter is not None):
            raise LeptrinoError("value", "digital_filter is given exactly for SET_DF")
        if self.digital_filter is not None:
            _check_u8("digital_filter", self.digital_filter)

    def payload(self) -> bytes:
        if self.command == Command.SET_DF:
            return bytes([8, self.sensor_no, self.command, 0, self.digital_filter, 0, 0, 0])
        return bytes([HEADER_LEN, self.sensor_no, self.command, 0])

    def encode(self) -> bytes:
        return frame(self.payload())


def encode_command(
    command: Command, sensor_no: int = BROADCAST_SENSOR_NO, digital_filter: int | None = None
) -> bytes:
    """A framed host command."""
    return CommandFrame(Command(command), sensor_no, digital_filter).encode()


def get_product_info() -> bytes:
    return encode_command(Command.GET_INF)


def get_rated_values() -> bytes:
    return encode_command(Command.GET_LIMIT)


def start_continuous_output() -> bytes:
    return encode_command(Command.DATA_START)


def stop_continuous_output() -> bytes:
    return encode_command(Command.DATA_STOP)


def set_digital_filter(value: int) -> bytes:
    return encode_command(Command.SET_DF, digital_filter=value)


def get_digital_filter() -> bytes:
    return encode_command(Command.GET_DF)


def parse_command(payload: bytes) -> CommandFrame:
    """Sensor side: a de-framed host command."""
    _check_len_byte(payload)
    cmd = payload[2]
    if cmd not in Command._value2member_map_:
        raise LeptrinoError("command", f"unknown command 0x{cmd:02X}")
    want = 8 if cmd == Command.SET_DF else HEADER_LEN
    if len(payload) != want:
        raise LeptrinoError("length", f"command 0x{cmd:02X} needs {want} bytes, got {len(payload)}")
    return CommandFrame(Command(cmd), payload[1], payload[4] if cmd == Command.SET_DF else None)


# ---------------------------------------------------------------------------------- responses


@dataclass(frozen=True)
class Ack:
    """Header-only response (e.g. to DATA_STOP, SET_DF, or any error result)."""

    command: int
    result: int = Result.OK
    term_no: int = 0


@dataclass(frozen=True)
class ProductInfo:
    product_name: str
    serial: str
    firmware_version: str
    output_rate: str
    result: int = Result.OK
    term_no: int = 0


@dataclass(frozen=True)
class RatedValues:
    """Rated (full-scale) values, N and N m, as float32 (fx, fy, fz, mx, my, mz)."""

    limits: tuple[float, ...]
    result: int = Result.OK
    term_no: int = 0


@dataclass(frozen=True)
class DigitalFilter:
    digital_filter: int
    result: int = Result.OK
    term_no: int = 0


@dataclass(frozen=True)
class ForceData:
    """One continuous-output sample: raw int16 (fx, fy, fz, mx, my, mz), temperature, status."""

    raw: tuple[int, ...]
    temperature: int = 0
    status: int = 0
    result: int = Result.OK
    term_no: int = 0

    def wrench(self, model: SensorModel | str, offset: Sequence[float] = (0,) * 6) -> tuple:
        return to_wrench(self.raw, model, offset)


Response = Ack | ProductInfo | RatedValues | DigitalFilter | ForceData

_DATA_FMT = "<6hhBx"
#: Payload length of a continuous-output sample: header + 6 raw counts, temperature, status.
FORCE_PAYLOAD_LEN = HEADER_LEN + struct.calcsize(_DATA_FMT)


def is_ok_sample(payload: bytes) -> bool:
    """True when :func:`parse_response` returns a :class:`ForceData` with result OK for
    ``payload`` (length, command and result bytes of a continuous-output sample)."""
    return (
        len(payload) == FORCE_PAYLOAD_LEN
        and payload[0] == FORCE_PAYLOAD_LEN
        and payload[2] == Command.DATA_START
        and payload[3] == Result.OK
    )


_INFO_SIZES = (PRODUCT_NAME_SIZE, SERIAL_SIZE, FIRMWARE_VERSION_SIZE, OUTPUT_RATE_SIZE)


def _check_u8(name: str, value: Any) -> None:
    if not isinstance(value, int) or isinstance(value, bool) or not 0 <= value <= 0xFF:
        raise LeptrinoError("value", f"{name}={value!r} not in 0..255")


def _check_len_byte(payload: bytes) -> None:
    if len(payload) < HEADER_LEN:
        raise LeptrinoError("length", f"payload of {len(payload)} bytes is shorter than a header")
    if payload[0] != len(payload):
        raise LeptrinoError("length", f"length byte {payload[0]} != payload length {len(payload)}")


def _ascii(name: str, text: str, size: int) -> bytes:
    raw = text.encode("ascii", errors="strict") if isinstance(text, str) else b"?"
    if len(raw) > size:
        raise LeptrinoError("value", f"{name}={text!r} longer than {size} bytes")
    return raw.ljust(size, b"\0")


def encode_response(resp: Response) -> bytes:
    """Sensor side: frame a response."""
    for name in ("result", "term_no"):
        _check_u8(name, getattr(resp, name))
    if isinstance(resp, Ack):
        _check_u8("command", resp.command)
        return frame(bytes([HEADER_LEN, resp.term_no, resp.command, resp.result]))
    if isinstance(resp, ProductInfo):
        cmd = Command.GET_INF
        body = b"".join(
            _ascii(n, getattr(resp, n), size)
            for n, size in zip(
                ("product_name", "serial", "firmware_version", "output_rate"),
                _INFO_SIZES,
                strict=True,
            )
        )
    elif isinstance(resp, RatedValues):
        cmd = Command.GET_LIMIT
        if len(resp.limits) != 6 or not all(math.isfinite(v) for v in resp.limits):
            raise LeptrinoError("value", f"limits must be 6 finite floats: {resp.limits!r}")
        body = struct.pack("<6f", *resp.limits)
    elif isinstance(resp, DigitalFilter):
        cmd = Command.GET_DF
        _check_u8("digital_filter", resp.digital_filter)
        body = bytes([resp.digital_filter, 0, 0, 0])
    elif isinstance(resp, ForceData):
        cmd = Command.DATA_START
        if len(resp.raw) != 6:
            raise LeptrinoError("value", f"raw must hold 6 values: {resp.raw!r}")
        try:
            body = struct.pack(_DATA_FMT, *resp.raw, resp.temperature, resp.status)
        except struct.error as exc:
            raise LeptrinoError("value", f"force data out of range: {exc}") from None
    else:
        raise LeptrinoError("value", f"not a Leptrino response: {resp!r}")
    head = bytes([HEADER_LEN + len(body), resp.term_no, cmd, resp.result])
    return frame(head + body)


def parse_response(payload: bytes) -> Response:
    """Host side: a de-framed sensor response to its typed dataclass."""
    _check_len_byte(payload)
    _, term, cmd, result = payload[:4]
    body = payload[4:]
    if cmd not in Command._value2member_map_:
        raise LeptrinoError("command", f"unknown command 0x{cmd:02X}")
    if not body:
        return Ack(cmd, result, term)
    sizes = {
        Command.GET_INF: sum(_INFO_SIZES),
        Command.GET_LIMIT: 24,
        Command.GET_DF: 4,
        Command.DATA_START: FORCE_PAYLOAD_LEN - HEADER_LEN,
    }
    if cmd not in sizes or len(body) != sizes[cmd]:
        raise LeptrinoError(
            "length", f"response 0x{cmd:02X} body of {len(body)} bytes (want {sizes.get(cmd, 0)})"
        )
    if cmd == Command.GET_INF:
        parts, at = [], 0
        for size in _INFO_SIZES:
            parts.append(body[at : at + size].split(b"\0", 1)[0].decode("ascii", "replace"))
            at += size
        return ProductInfo(*parts, result=result, term_no=term)
    if cmd == Command.GET_LIMIT:
        return RatedValues(struct.unpack("<6f", body), result, term)
    if cmd == Command.GET_DF:
        return DigitalFilter(body[0], result, term)
    *raw, temperature, status = struct.unpack(_DATA_FMT, body)
    return ForceData(tuple(raw), temperature, status, result, term)


# --------------------------------------------------------------------------------- conversion


@dataclass(frozen=True)
class SensorModel:
    """Rated values (fx, fy, fz in N; mx, my, mz in N m): raw 10000 = rated."""

    name: str
    rated: tuple[float, float, float, float, float, float]


MODELS: dict[str, SensorModel] = {
    m.name: m
    for m in (
        # The paper's foot sensor: +-150 N xy, +-300 N z, +-4.0 N m.
        SensorModel("CFS034CA301U", (150.0, 150.0, 300.0, 4.0, 4.0, 4.0)),
        # The paper's end-effector sensor: +-100 N xy, +-200 N z, +-1.0 N m.
        SensorModel("CFS018CA201U", (100.0, 100.0, 200.0, 1.0, 1.0, 1.0)),
        SensorModel("PFS055YA501U6", (500.0, 500.0, 500.0, 10.0, 10.0, 8.0)),
        SensorModel("PFS080YS102U6", (500.0, 500.0, 1000.0, 40.0, 40.0, 30.0)),
    )
}
#: the foot sensor of the robot (the fuzz harness scales its wrenches with it)
FOOT_SENSOR = MODELS["CFS034CA301U"]
END_EFFECTOR_SENSOR = MODELS["CFS018CA201U"]


def _model(model: SensorModel | str) -> SensorModel:
    if isinstance(model, SensorModel):
        return model
    if model not in MODELS:
        raise LeptrinoError("value", f"unknown sensor model {model!r} (known: {sorted(MODELS)})")
    return MODELS[model]


def to_wrench(
    raw: Sequence[float], model: SensorModel | str, offset: Sequence[float] = (0,) * 6
) -> tuple[float, ...]:
    """``(raw - offset) * rated / 10000`` per axis: (fx, fy, fz) N, (mx, my, mz) N m."""
    rated = _model(model).rated
    if len(raw) != 6 or len(offset) != 6:
        raise LeptrinoError("value", "raw and offset need 6 values each")
    return tuple((r - o) * k / RAW_AT_RATED for r, o, k in zip(raw, offset, rated, strict=True))


def cfs_node_wrench(
    raw: Sequence[int], model: SensorModel | str, offset: Sequence[float] = (0,) * 6
) -> tuple[float, ...]:
    """The JSK ``cfs_sensor`` node's result: truncated to integer mN / uN m, then scaled back."""
    rated = _model(model).rated
    out = []
    for axis, (r, o, k) in enumerate(zip(raw, offset, rated, strict=True)):
        if axis < 3:
            out.append(math.trunc((r - o) * k * 1000 / 10000) / 1000.0)
        else:
            out.append(math.trunc((r - o) * k * 1000 / 10) / 1_000_000.0)
    return tuple(out)


def from_wrench(wrench: Sequence[float], model: SensorModel | str) -> tuple[int, ...]:
    """Sensor side: the raw int16 counts for a wrench (rounded; out of int16 range raises)."""
    rated = _model(model).rated
    if len(wrench) != 6 or not all(math.isfinite(w) for w in wrench):
        raise LeptrinoError("value", f"wrench must be 6 finite values: {wrench!r}")
    raw = tuple(round(w * RAW_AT_RATED / k) for w, k in zip(wrench, rated, strict=True))
    for axis, r in enumerate(raw):
        if not -0x8000 <= r <= 0x7FFF:
            raise LeptrinoError("value", f"axis {axis}: {wrench[axis]} saturates the int16 raw")
    return raw


# ------------------------------------------------------------------------------------ decoder


def _fields(obj: Any) -> dict[str, Any]:
    out = {}
    for key, value in vars(obj).items():
        out[key] = list(value) if isinstance(value, tuple) else value
        if isinstance(value, enum.Enum):
            out[key] = value.name
    return out


_KINDS = {
    Ack: "ack",
    ProductInfo: "product_info",
    RatedValues: "rated_values",
    DigitalFilter: "digital_filter",
    ForceData: "force_data",
    CommandFrame: "command",
}


def decode_leptrino(
    data: bytes, *, from_sensor: bool = True, parser: LeptrinoStreamParser | None = None
) -> Iterator[dict[str, Any]]:
    """Yield one dict per frame (or framing/payload error) found in ``data``.

    Keys: ``offset`` (of the frame's DLE), ``kind`` (None on error), ``ok``, ``error``,
    ``payload`` (hex) and the decoded fields. ``from_sensor=False`` decodes host commands.
    """
    p = parser if parser is not None else LeptrinoStreamParser()
    for event in p.feed(data):
        if event.error is not None:
            yield {"offset": event.offset, "kind": None, "ok": False, "error": str(event.error)}
            continue
        payload = event.payload or b""
        try:
            obj: Any = parse_response(payload) if from_sensor else parse_command(payload)
        except LeptrinoError as exc:
            p.errors[exc.reason] += 1
            yield {
                "offset": event.offset,
                "kind": None,
                "ok": False,
                "error": str(exc),
                "payload": payload.hex(),
            }
            continue
        yield {
            "offset": event.offset,
            "kind": _KINDS[type(obj)],
            "ok": True,
            "error": None,
            "payload": payload.hex(),
            **_fields(obj),
        }
