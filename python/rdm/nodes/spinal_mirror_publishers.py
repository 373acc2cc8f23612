"""The Spinal mirror's periodic publications (``imu``, ``battery_voltage_status``,
``motor_pwms``, ``servo/states``, ``servo/torque_states``) and its rosserial log messages, at
the firmware's periods; the ``imu`` and ``servo/states`` frames built in Rust when they can be
(the same bytes as the message path).

:class:`SpinalPublishers` is a part of :class:`rdm.nodes.spinal_mirror.SpinalMirror`: its
methods read the mirror's state (``session``, ``counters``, ``last_output``, ``duties`` ...).
"""

from __future__ import annotations

from typing import Any

from rdm._rdm import spinal_imu_frame as _imu_frame
from rdm.protocol.rosserial import constants as C
from rdm.protocol.rosserial.timesync import ClientClock

#: Publication periods in HAL ms and whether the firmware compares with ``>`` (strict).
IMU_PUB_MS = 5  # >= 5 ms (200 Hz), attitude_estimate.h
BATTERY_PUB_MS = 100  # > 100 ms, battery_status.h
MOTOR_PWMS_PUB_MS = 100  # > 100 ms, attitude_control.cpp
SERVO_STATES_PUB_MS = 20  # >= 20 ms (50 Hz), spine.cpp
SERVO_TORQUE_PUB_MS = 1000  # >= 1000 ms

#: The next due ms of a publisher that never published (due at once).
_NEVER = -(2**62)


#: The generated layout of ``spinal/Imu`` that ``rdm._rdm.spinal_imu_frame`` packs.
_IMU_SIGNATURE = (
    (
        "fixed",
        (
            ("stamp", "t", None),
            ("acc", "a", 3),
            ("gyro", "a", 3),
            ("mag", "a", 3),
            ("quaternion", "a", 4),
        ),
        "II3f3f3f4f",
    ),
)


class SpinalPublishers:
    """The publishers of :class:`rdm.nodes.spinal_mirror.SpinalMirror` (a part of it)."""

    def _publish(self, now_ms: int) -> None:
        if not self.session.configured or self.last_output is None:
            return
        state = self._state
        if now_ms < state.next_pub_ms:
            return  # no publisher due (exact: the earliest ms any check below fires)
        state.next_pub_ms = self._publish_due(now_ms)

    def _publish_due(self, now_ms: int) -> int:
        """Each publisher due at ``now_ms`` publishes, in this order, and stamps its
        ``_last_pub``: ``imu`` (every >= 5 ms), ``battery_voltage_status`` (> 100 ms),
        ``motor_pwms`` (> 100 ms), ``servo/states`` (>= 20 ms), ``servo/torque_states``
        (>= 1000 ms), the firmware's comparisons. Returns the first ms one is due again."""
        last = self._last_pub
        get = last.get
        stamp = None
        t = get("imu")
        if t is None or now_ms - t >= IMU_PUB_MS:
            last["imu"] = t = now_ms
            if not self._publish_imu_frame(now_ms):
                stamp = self.session.now(now_ms)
                self._publish_topic("imu", self._imu_message(stamp))
        next_ms = t + IMU_PUB_MS
        t = get("battery_voltage_status")
        if t is None or now_ms - t > BATTERY_PUB_MS:
            last["battery_voltage_status"] = t = now_ms
            if self.battery_voltage is not None:
                self._publish_topic(
                    "battery_voltage_status", self._msg.float32.new(data=self.battery_voltage)
                )
        next_ms = min(next_ms, t + BATTERY_PUB_MS + 1)
        t = get("motor_pwms")
        if t is None or now_ms - t > MOTOR_PWMS_PUB_MS:
            last["motor_pwms"] = t = now_ms
            values = [int(d * 2000.0) for d in self.duties]
            self._publish_topic("motor_pwms", self._msg.pwms.new(motor_value=values))
        next_ms = min(next_ms, t + MOTOR_PWMS_PUB_MS + 1)
        t = get("servo/states")
        if t is None or now_ms - t >= SERVO_STATES_PUB_MS:
            last["servo/states"] = t = now_ms
            if stamp is None:
                stamp = self.session.now(now_ms)
            if not self._publish_servo_states_frame(stamp):
                msg = self.servos.states(self._msg, stamp)
                if msg is not None:
                    self._publish_topic("servo/states", msg)
        next_ms = min(next_ms, t + SERVO_STATES_PUB_MS)
        t = get("servo/torque_states")
        if t is None or now_ms - t >= SERVO_TORQUE_PUB_MS:
            last["servo/torque_states"] = t = now_ms
            msg = self.servos.torque_states(self._msg)
            if msg is not None:
                self._publish_topic("servo/torque_states", msg)
        return min(next_ms, t + SERVO_TORQUE_PUB_MS)

    def _publish_imu_frame(self, now_ms: int) -> bool:
        """The ``imu`` publication of :meth:`_publish_due` as one frame built in Rust
        (``rdm._rdm.spinal_imu_frame``: stamp, message, frame and checksums): the same bytes,
        TX ring and counters. False, having done nothing, when that path does not apply
        (another publisher codec or clock class, values it declines)."""
        session = self.session
        clock = session.clock
        if clock.__class__ is not ClientClock:
            return False
        try:
            slot = session.publisher("imu")
        except KeyError:
            return False  # the message path raises it
        codec = slot.codec
        if codec is not self._imu_codec:
            if codec.layout.signature() != _IMU_SIGNATURE:
                return False
            self._imu_codec = codec
        topic_id = slot.topic_id
        frame = _imu_frame(
            topic_id,
            now_ms,
            clock.synced,
            clock._sync_tick,
            clock._sync_ns,
            self.acc,
            self.last_output,
            self.mag,
        )
        if frame is None:
            return False
        if session.send_frame(topic_id, frame) > 0:
            self.counters.published["imu"] += 1
        return True

    def _publish_servo_states_frame(self, stamp: Any) -> bool:
        """The ``servo/states`` publication built from the servo table without message
        objects (``ServoBridge.states_frame``): the same frame and counters. False, having
        done nothing, when that path does not apply."""
        session = self.session
        try:
            slot = session.publisher("servo/states")
        except KeyError:
            return False  # the message path raises it (if a servo reports)
        codec = slot.codec
        if codec is not self._msg.servo_states:
            return False
        topic_id = slot.topic_id
        frame = self.servos.states_frame(codec, stamp, topic_id)
        if frame is False:
            return False
        if frame is not None and session.send_frame(topic_id, frame) > 0:
            self.counters.published["servo/states"] += 1
        return True

    def _imu_message(self, stamp: Any) -> Any:
        """The ``spinal/Imu`` message of the present sample and estimate."""
        out = self.last_output
        return self._msg.imu.new(
            stamp=stamp,
            acc=list(self.acc),
            gyro=out.angular_velocity.tolist(),
            mag=list(self.mag),
            quaternion=out.quaternion.tolist(),
        )

    def _publish_topic(self, topic: str, msg: Any) -> None:
        if self.session.publish(topic, msg) > 0:
            self.counters.published[topic] += 1

    def _log(self, level: int, text: str) -> None:
        self.counters.logs[C.LogLevel(level).name.lower()] += 1
        self.session.log(level, text)
