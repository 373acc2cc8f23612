"""The onboard node's receive side: the rosserial events from Spinal (``imu``, ``servo/states``,
``servo/torque_states``, ``flight_config_ack``, ``battery_voltage_status``, the ``imu_calib``
answer, a lost sync, the ``"CAN disconnected!!"`` log), the ``imu`` and ``servo/states``
payloads read without the codec, and the cache of servo readings seen before.

:class:`OnboardReceive` is a part of :class:`rdm.nodes.onboard.OnboardNode`: its methods read
and write the node's state (``present_q``, ``counts``, ``arming``, ``config`` ...).
"""

from __future__ import annotations

import math
import struct
from typing import Any, NamedTuple

import numpy as np

from rdm.nodes.onboard_arming import FlightState
from rdm.nodes.onboard_calibration import GET_CALIB_DATA
from rdm.nodes.onboard_operator import _vector
from rdm.protocol.rosserial.constants import LogLevel
from rdm.protocol.rosserial.events import (
    LogReceived,
    MessageReceived,
    ServiceResponse,
    SyncLost,
)
from rdm.protocol.rosserial.services import ServiceError

#: How many distinct ``servo/states`` readings the node keeps the joint writes of.
SERVO_CACHE_SIZE = 8
#: Largest joint change between two ``servo/states`` readings taken as real, rad. ASSUMPTION:
#: Spinal reports at 25-50 Hz and a Dynamixel X turns at most ~6 rad/s unloaded, so a real
#: reading moves a joint by at most ~0.25 rad; a larger jump is a damaged frame.
SERVO_JUMP_MAX_RAD = 0.35
#: Implausible readings in a row after which the next one is taken (the joint did move).
SERVO_REJECTS_MAX = 3
#: Spinal's only report of its Neuron bus (``Spine::update``, jsk-wire-protocols.md sec. 2.6):
#: a ``logerror`` once no CAN frame arrived for 100 ms, repeated at most once a second (the
#: Spinal mirror's timing; another revision of ``Spine::update`` logs it 1 s after the bus is
#: declared disconnected). It publishes no CAN error counter or bus state, and
#: ``servo/states`` goes on every 20 ms from the values last received, so frame loss and a
#: shorter bus-off show the node nothing.
CAN_DISCONNECTED_LOG = "CAN disconnected!!"
#: ``spinal/Imu`` payload from byte 20: gyro (3 float32), mag skipped, quaternion (4 float32).
_IMU_GYRO_QUAT = struct.Struct("<3f12x4f")
#: ``spinal/Imu`` payload from byte 8: the accelerometer (3 float32, m/s^2).
_IMU_ACC = struct.Struct("<3f")
_U32 = struct.Struct("<I")
#: ``spinal/ServoStates``: stamp (8 bytes), count (uint32), 7 bytes per ``spinal/ServoState``.
_SERVO_STATES_HEAD, _SERVO_STATE_SIZE = 12, 7
#: ``spinal/ServoState``'s index (uint8) and angle (int16); temp, load, error skipped.
_SERVO_INDEX_ANGLE = struct.Struct("<Bh4x")
_SERVO_STATE_FIELDS = [
    ("index", "uint8", None),
    ("angle", "int16", None),
    ("temp", "uint8", None),
    ("load", "int16", None),
    ("error", "uint8", None),
]


class _ServoReading(NamedTuple):
    """The two fields of a ``spinal/ServoState`` the node reads."""

    index: int
    angle: int


class _ServoReadings:
    """What :meth:`OnboardNode._on_servo_states` reads of a decoded ``spinal/ServoStates``."""

    __slots__ = ("servos",)

    def __init__(self, servos: list[_ServoReading]) -> None:
        self.servos = servos


def quaternion_to_euler(x: float, y: float, z: float, w: float) -> tuple[float, float, float]:
    """Roll, pitch, yaw (ZYX) of a unit quaternion."""
    roll = math.atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2.0 * (w * y - z * x))))
    yaw = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    return roll, pitch, yaw


def servo_states_decodes(payload: bytes) -> bool:
    """Whether ``spinal/ServoStates`` decodes ``payload`` (a stamp, a count and exactly that
    many 7-byte entries; anything shorter or longer is a decode error)."""
    n = len(payload)
    if n < _SERVO_STATES_HEAD:
        return False
    return n - _SERVO_STATES_HEAD == _SERVO_STATE_SIZE * _U32.unpack_from(payload, 8)[0]


class OnboardReceive:
    """What the node takes in from Spinal (a part of :class:`rdm.nodes.onboard.OnboardNode`)."""

    #: Implausible ``servo/states`` readings in a row (:meth:`_servo_plausible`).
    _servo_rejects = 0

    @property
    def imu_euler(self) -> tuple[float, float, float] | None:
        """Roll, pitch, yaw of the newest valid ``imu`` quaternion (None before one)."""
        if self._imu_euler is None and self._imu_quat is not None:
            x, y, z, w = self._imu_quat
            self._imu_euler = quaternion_to_euler(x, y, z, w)
        return self._imu_euler

    @property
    def imu_gyro(self) -> np.ndarray | None:
        """The newest valid ``imu`` gyro vector [rad/s] (None before one)."""
        if self._gyro_src is not None:
            self._imu_gyro, self._gyro_src = np.array(self._gyro_src), None
        return self._imu_gyro

    def _read_imu_calibration(self, now: float) -> None:
        """Ask Spinal for its IMU calibration (once per handshake, retried until answered)."""
        if not self.config.read_imu_calibration or not self.imu_calibration.request(now):
            return
        try:
            self.session.call_service(
                "imu_calib", self._imu_calib_request.new(command=GET_CALIB_DATA, data=[]), now
            )
        except ServiceError:  # not offered (yet) or a call still pending: the retry asks again
            self.imu_calibration.counts["call_refused"] += 1

    def _on_event(self, event: Any) -> None:
        if isinstance(event, SyncLost):
            self.counts["sync_lost"] += 1
            self._link_up_at = None
            self.arming.link_lost()
            self._announced = False
            self.imu_calibration.reset()
            return
        if isinstance(event, LogReceived):
            if event.level >= LogLevel.ERROR and event.text == CAN_DISCONNECTED_LOG:
                self.monitors.trip("can_disconnected", f"Spinal: {event.text}", self._now)
                self._react("can_disconnected", self._now)
            return
        if isinstance(event, ServiceResponse):
            if event.service == "imu_calib":
                r = event.response
                self.imu_calibration.on_response(bool(r.success), r.data)
            return
        if not isinstance(event, MessageReceived):
            return
        msg = event.message
        self.counts[f"rx:{event.topic}"] += 1
        if event.topic == "imu":
            q = [float(v) for v in msg.quaternion]
            if not all(map(math.isfinite, q)) or abs(math.fsum([v * v for v in q]) - 1) > 0.1:
                self.counts["imu_invalid"] += 1
                return
            acc = [float(v) for v in msg.acc]
            g = msg.gyro
            exact = type(g) in (tuple, list) and len(g) == 3 and all(type(v) is float for v in g)
            # what _vector accepts; an exact float list converted when read
            arr = None if exact else _vector(g, 3)
            finite = all(map(math.isfinite, g)) if exact else arr is not None
            gyro = (list(g) if exact else arr.tolist()) if finite else None  # type: ignore[union-attr]
            if not self.monitors.imu_plausible(self._now, acc, gyro, q):
                return
            self._imu_quat, self._imu_euler = q, None
            self._imu_at, self._imu_acc = self._now, acc
            if exact and finite:
                self._gyro_src = g
            elif arr is not None:
                self._gyro_src, self._imu_gyro = None, arr
        elif event.topic == "servo/states":
            self._on_servo_states(msg)
        elif event.topic == "servo/torque_states":
            flags = [bool(v) for v in msg.torque_enable]
            indices = self.config.servo_map.servo_index
            self.servos_torque_on = all(i < len(flags) and flags[i] for i in indices)
        elif event.topic == "flight_config_ack":
            before = self.arming.state
            self.arming.on_ack(int(msg.data))
            if before is not FlightState.ARMED and self.arming.state is FlightState.ARMED:
                self.control.reset_integrators()
        elif event.topic == "battery_voltage_status":
            v = float(msg.data)
            if self.monitors.battery(v, self._now):
                self.battery_voltage = v
            else:
                self.counts["battery_invalid"] += 1

    def _on_imu_payload(self, payload: bytes) -> None:
        """An ``imu`` message from its payload (one the codec decodes): what ``_on_event`` does
        with the decoded message, reading only the accelerometer, the gyro and the quaternion;
        a reading :meth:`Monitors.imu_plausible` refuses is not taken."""
        self.counts["rx:imu"] += 1
        gx, gy, gz, x, y, z, w = _IMU_GYRO_QUAT.unpack_from(payload, 20)
        q = [x, y, z, w]
        if not all(map(math.isfinite, q)) or abs(math.fsum((x * x, y * y, z * z, w * w)) - 1) > 0.1:
            self.counts["imu_invalid"] += 1
            return
        acc = list(_IMU_ACC.unpack_from(payload, 8))
        g = [gx, gy, gz]
        finite = all(map(math.isfinite, g))
        if not self.monitors.imu_plausible(self._now, acc, g if finite else None, q):
            return
        self._imu_quat, self._imu_euler = q, None
        self._imu_at, self._imu_acc = self._now, acc
        if finite:
            self._gyro_src = g

    def _on_servo_payload(self, payload: bytes) -> None:
        """A ``servo/states`` message from its payload (one the codec decodes): a reading seen
        before (same bytes after the stamp) applied from its cached entry, else decoded."""
        self.counts["rx:servo/states"] += 1
        self._servo_cache_valid()
        body = payload[8:]
        hit = self._servo_raw.get(body)
        if hit is not None:
            self._apply_servo_entry(hit)
            return
        if self._servo_struct and servo_states_decodes(payload):
            # the index and angle of each entry, as the codec decodes them (uint8, int16)
            readings = _SERVO_INDEX_ANGLE.iter_unpack(memoryview(payload)[_SERVO_STATES_HEAD:])
            msg = _ServoReadings(list(map(_ServoReading._make, readings)))
        else:
            msg = self._servo_codec.decode(payload)
        entry = self._on_servo_states(msg)
        if entry is not None:
            raw = self._servo_raw
            raw[body] = entry
            if len(raw) > SERVO_CACHE_SIZE:
                del raw[next(iter(raw))]  # the oldest

    def _servo_cache_valid(self) -> None:
        """Forget the cached servo entries when the servo map object changed."""
        smap = self.config.servo_map
        if smap is not self._servo_cache_map:
            self._servo_cache.clear()
            self._servo_raw.clear()
            self._servo_cache_map = smap

    def _apply_servo_entry(self, entry: tuple[np.ndarray, np.ndarray, int, bool]) -> None:
        """One reading's joint values, unless implausible (:meth:`_servo_plausible`)."""
        joints, values, n_unknown, partial = entry
        if n_unknown:
            self.counts["servo_unknown_index"] += n_unknown
        if partial:
            self.counts["servo_states_partial"] += 1
        if not self._servo_plausible(joints, values):
            return
        self.present_q[joints] = values
        self._seen[joints] = True
        self._hold_present_q()

    def _servo_plausible(self, joints: np.ndarray, values: np.ndarray) -> bool:
        """False for a reading with a joint more than :data:`SERVO_JUMP_MAX_RAD` from its last
        accepted value (counted ``servo_states_implausible``): a frame damaged on the UART
        whose 8-bit checksums still pass, which the controller must not act on. After
        :data:`SERVO_REJECTS_MAX` rejections in a row the reading is taken (counted
        ``servo_states_resync``): the joint did move, or the last accepted value was wrong."""
        seen = self._seen[joints]
        if not seen.any():
            return True
        jump = np.abs(values[seen] - self.present_q[joints[seen]])
        if not (jump.max() > SERVO_JUMP_MAX_RAD):  # (a NaN never reaches here: to_rad is finite)
            self._servo_rejects = 0
            return True
        self._servo_rejects += 1
        if self._servo_rejects <= SERVO_REJECTS_MAX:
            self.counts["servo_states_implausible"] += 1
            return False
        self.counts["servo_states_resync"] += 1
        self._servo_rejects = 0
        return True

    def _on_servo_states(self, msg: Any) -> tuple[np.ndarray, np.ndarray, int, bool] | None:
        """Apply one decoded reading; returns its cache entry (None when not cacheable)."""
        smap = self.config.servo_map
        self._servo_cache_valid()
        try:
            key = tuple([(s.index, s.angle) for s in msg.servos])
            hit = self._servo_cache.get(key)
        except (TypeError, AttributeError):  # not hashable / not servo entries: the loop
            key = hit = None
        if hit is not None:
            self._apply_servo_entry(hit)
            return hit
        joints, values, n_unknown = [], [], 0
        for s in msg.servos:
            joint = smap.joint_of(int(s.index))
            if joint is None or joint >= self.robot.n_q:
                n_unknown += 1
                continue
            joints.append(joint)
            values.append(smap.to_rad(joint, int(s.angle)))
        covered = set(joints)
        entry = (
            np.array(joints, dtype=np.intp),
            np.array(values, dtype=float),
            n_unknown,
            len(covered) != self.robot.n_q,
        )
        cacheable = key is not None and len(covered) == len(joints)  # no joint written twice
        if cacheable:
            cache = self._servo_cache
            cache[key] = entry
            if len(cache) > SERVO_CACHE_SIZE:
                del cache[next(iter(cache))]  # the oldest
        self._apply_servo_entry(entry)
        return entry if cacheable else None

    def _hold_present_q(self) -> None:
        """Once every joint has a reading and no target is known: hold where the arm is
        (:meth:`~rdm.nodes.onboard_operator.OnboardOperator._hold_joints`)."""
        if self.joint_targets is None and self._trajectory is None and self._seen.all():
            self._hold_joints(self.present_q)
