"""The onboard node's send side: every publish to Spinal with its refusals counted, the
payloads the node packs itself where the wire form is a plain struct (``four_axes/command``,
``rpy/gain``, ``servo/target_states``) and messages serialized once while unchanged, the
``uav_info`` / ``motor_info`` announcements, the arming commands, the servo torque-on, the
roll/pitch integration switch, the gains and the servo targets.

:class:`OnboardSend` is a part of :class:`rdm.nodes.onboard.OnboardNode`: its methods read
the node's state (``session``, ``config``, ``control``, ``arming`` ...) and count in
``published`` and ``counts``.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Callable, Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from rdm._rdm import servo_target_payload as _servo_target_payload
from rdm.nodes.onboard_arming import FlightState
from rdm.nodes.onboard_config import RP_HOLD_WINDOW_S, ServoMap
from rdm.nodes.onboard_control import ControlCommand
from rdm.nodes.onboard_receive import _U32
from rdm.protocol.rosserial.server import PayloadTooLarge, TopicNotNegotiated

#: ``spinal/FlightConfigCmd`` INTEGRATION_CONTROL_ON_CMD.
INTEGRATION_CONTROL_ON = 160
#: ``spinal/FlightConfigCmd`` INTEGRATION_CONTROL_OFF_CMD.
INTEGRATION_CONTROL_OFF = 161


def _floats(values: Any) -> list[float]:
    """``[float(v) for v in values]``; a float64 array's ``tolist`` gives the same floats."""
    if type(values) is np.ndarray and values.dtype == np.float64 and values.ndim == 1:
        return values.tolist()
    return [float(v) for v in values]


def _four_axis_payload(angles: Sequence[float], base_thrust: Any) -> bytes | None:
    """``spinal/FourAxisCommand`` bytes (float32[3] angles, float32[] base_thrust) of the
    values the message would carry; None when they do not pack (the codec raises then)."""
    thrust = _floats(base_thrust)
    try:
        return struct.pack(f"<3fI{len(thrust)}f", *angles, len(thrust), *thrust)
    except (struct.error, TypeError, OverflowError):
        return None


class OnboardSend:
    """What the node sends to Spinal (a part of :class:`rdm.nodes.onboard.OnboardNode`)."""

    def _publish(self, topic: str, msg: Any) -> bool:
        return self._send(self.session.publish, topic, msg)

    def _publish_payload(self, topic: str, payload: bytes) -> bool:
        """:meth:`_publish` of a message already serialized with the topic's codec."""
        session = self.session
        if session.try_publish_payload(topic, payload):
            self.published[topic] += 1  # as _send counts a send
            return True
        return self._send(session.publish_payload, topic, payload)

    def _send(self, publish: Callable[[str, Any], int], topic: str, what: Any) -> bool:
        """One publish: refusals counted per topic, sends counted in ``published``."""
        try:
            publish(topic, what)
        except TopicNotNegotiated:
            self.counts[f"not_negotiated:{topic}"] += 1
            return False
        except PayloadTooLarge:
            self.counts[f"too_large:{topic}"] += 1
            return False
        self.published[topic] += 1
        return True

    def _publish_same(self, topic: str, msg: Any) -> bool:
        """:meth:`_publish` of a message object the node never mutates: serialized once per
        codec (the topic's codec gives the same bytes for the same unchanged message)."""
        remote = self.session.outbound.get(topic)
        if remote is None:
            return self._publish(topic, msg)
        cached = self._payloads.get(topic)
        if cached is None or cached[0] is not msg or cached[1] is not remote.codec:
            cached = self._payloads[topic] = (msg, remote.codec, remote.codec.encode(msg))
        return self._publish_payload(topic, cached[2])

    def _direct_remote(self, topic: str, type_name: str) -> bool:
        """Whether ``topic`` may be sent as a payload the node packs itself: the device
        subscribes to it with ``type_name`` (else the codec path, which raises or counts)."""
        remote = self.session.outbound.get(topic)
        return remote is not None and remote.type == type_name

    def _info_message(self, topic: str) -> Any:
        """``uav_info`` or ``motor_info`` from the configuration."""
        c = self.config
        if topic == "uav_info":
            return self._msg[topic].new(motor_num=c.motor_num, uav_model=c.uav_model)
        p = c.pwm_info
        units = [
            self._msg["motor_unit"].new(
                voltage=float(r[0]),
                max_thrust=float(r[1]),
                polynominal=[float(v) for v in r[2:7]],
            )
            for r in p.motor_info
        ]
        return self._msg[topic].new(
            min_pwm=p.min_pwm,
            max_pwm=p.max_pwm,
            min_thrust=p.min_thrust,
            force_landing_thrust=p.force_landing_thrust,
            pwm_conversion_mode=p.mode,
            motor_info=units,
        )

    def _arming_messages(self, now: float) -> None:
        for topic, cmd in self.arming.due(now):
            if topic in ("uav_info", "motor_info"):
                msg = self._info_message(topic)
            else:
                msg = self._msg[topic].new(cmd=int(cmd))
            if self._publish(topic, msg):
                self.arming.sent(topic, now)

    def _torque_on(self, now: float) -> None:
        """``servo/torque_enable`` for every mapped servo once Spinal's servo table is up (its
        ``servo/states`` arrive), re-sent until ``servo/torque_states`` shows them all on."""
        if not self.config.servo_torque_on_start or self.servos_torque_on:
            return
        if self.counts["rx:servo/states"] == 0:
            return
        if self._torque_sent_at is not None and now - self._torque_sent_at < (
            self.config.torque_retry_s
        ):
            return
        indices = list(self.config.servo_map.servo_index)
        msg = self._msg["servo/torque_enable"].new(index=indices, torque_enable=[1] * len(indices))
        if self._publish("servo/torque_enable", msg):
            self._torque_sent_at = now
            self.counts["torque_enable_sent"] += 1

    def _rp_integration(self, z: float) -> None:
        """Spinal integrates roll/pitch only after INTEGRATION_CONTROL_ON (160), which JSK
        sends once the robot is ``start_rp_integration_height`` above its take-off height.
        Then, with ``rp_integration_hold_rate``, :meth:`_rp_integration_hold`."""
        if self.arming.state is not FlightState.ARMED:
            return
        if self.integration_on_sent:
            self._rp_integration_hold()
            return
        if self._arm_z is None:
            self._arm_z = z
        elif z - self._arm_z >= self.config.rp_integration_height:
            msg = self._msg["flight_config_cmd"].new(cmd=INTEGRATION_CONTROL_ON)
            self.integration_on_sent = self._publish("flight_config_cmd", msg)

    def _rp_integration_hold(self) -> None:
        """INTEGRATION_CONTROL_OFF (161) while the IMU link turns against the CoG frame
        (the angle between the model's C<-IMU rotations :data:`RP_HOLD_WINDOW_S` apart, over
        that time) faster than ``rp_integration_hold_rate``, INTEGRATION_CONTROL_ON (160)
        once slower; counted ``rp_integration_held`` / ``rp_integration_resumed``."""
        limit = self.config.rp_integration_hold_rate
        terms = self.control.terms
        if limit is None or terms is None:
            return
        now, rot = self._now, terms.imu_to_cog
        ref = self._imu_cog_ref
        if ref is None:
            self._imu_cog_ref = (now, rot)
            return
        span = now - ref[0]
        if span < RP_HOLD_WINDOW_S - 1e-9:
            return
        self._imu_cog_ref = (now, rot)
        cos = (float(np.trace(rot @ ref[1].T)) - 1.0) / 2.0
        rate = math.acos(max(-1.0, min(1.0, cos))) / span
        hold = rate > limit
        if hold == self.rp_integration_held:
            return
        cmd = INTEGRATION_CONTROL_OFF if hold else INTEGRATION_CONTROL_ON
        if self._publish("flight_config_cmd", self._msg["flight_config_cmd"].new(cmd=cmd)):
            self.rp_integration_held = hold
            self.counts["rp_integration_held" if hold else "rp_integration_resumed"] += 1

    def _send_command(self, c: ControlCommand) -> None:
        limit = self.config.flight.max_tilt_cmd
        roll, pitch, yaw_term = c.angles
        limited = abs(roll) > limit or abs(pitch) > limit
        reason = f"roll/pitch target beyond {limit} rad"
        self.monitors.stale("tilt_limit", limited, self._now, reason)
        if limited:  # saturate below Spinal's 1 rad tilt fail-safe
            self.counts["tilt_limited"] += 1
            roll, pitch = max(-limit, min(limit, roll)), max(-limit, min(limit, pitch))
            c = replace(c, angles=(roll, pitch, yaw_term))
        if self._direct_remote("four_axes/command", "spinal/FourAxisCommand"):
            payload = _four_axis_payload(c.angles, c.base_thrust)
            if payload is not None:
                self._publish_payload("four_axes/command", payload)
                return
        self._publish(
            "four_axes/command",
            self._msg["four_axes/command"].new(
                angles=list(c.angles), base_thrust=_floats(c.base_thrust)
            ),
        )

    def _send_gains(self) -> None:
        """``rpy/gain`` from the pipeline's wire gains; while a lost rotor is arrested its
        roll and pitch P/I/D go out zero (Spinal's loop stops the turn with the other
        rotors; a rotor that comes back, a reset Neuron's, gets only the thrust floor)."""
        wire = self.control.gains_wire
        assert wire is not None
        lost = self.lost_rotor if self.rotor_lost_at is not None else None
        if lost is not None and wire.ndim == 2 and 0 <= lost < wire.shape[0]:
            wire = wire.copy()
            wire[lost, :6] = 0  # roll_p .. pitch_d; yaw_d kept
        if (
            wire.dtype == np.int16
            and wire.ndim == 2
            and wire.shape[1] == 7
            and self._direct_remote("rpy/gain", "spinal/RollPitchYawTerms")
        ):
            # count, then 7 int16 per motor (roll_p .. yaw_d): the codec's bytes for the
            # RollPitchYawTerm messages built below (built by the core with these terms)
            built = self.control.gains_payload
            if built is not None and built[0] is wire:
                payload = built[1]
            else:
                payload = _U32.pack(wire.shape[0]) + wire.astype("<i2", copy=False).tobytes()
            self._publish_payload("rpy/gain", payload)
            return
        key = (wire.tobytes(), wire.dtype.str, wire.shape)
        if self._gains_msg is None or self._gains_msg[0] != key:
            term = self._msg["rpy_term"]
            names = ("roll_p", "roll_i", "roll_d", "pitch_p", "pitch_i", "pitch_d", "yaw_d")
            # integer arrays: tolist() gives the same Python ints as int(v), without numpy scalars
            rows = wire.tolist() if wire.dtype.kind in "iu" else wire
            motors = [
                term.new(**{k: int(v) for k, v in zip(names, row, strict=True)}) for row in rows
            ]
            self._gains_msg = (key, self._msg["rpy/gain"].new(motors=motors))
        self._publish("rpy/gain", self._gains_msg[1])

    def _send_servo_targets(self, targets: np.ndarray) -> None:
        """``servo/target_states``: the joint targets, in flight the vectoring joints written
        over with the last command's angles, each to raw ticks (:meth:`ServoMap.to_raw`); the
        goals kept in ``last_servo_goals``. One Rust call (``rdm._rdm.servo_target_payload``)
        packs the payload for a :class:`ServoMap` when Spinal subscribes with
        ``spinal/ServoControlCmd``; what it declines (another map type or message type, a
        target or index the wire cannot carry) goes through the codec, which raises or
        counts."""
        arr = np.array(targets, dtype=float)
        smap = self.config.servo_map
        vectoring = self.last_alpha_beta if self.arming.flying else None
        if smap.__class__ is ServoMap and self._direct_remote(
            "servo/target_states", "spinal/ServoControlCmd"
        ):
            done = _servo_target_payload(
                arr,
                vectoring,
                self.control.vectoring_joints,
                smap.zero_point,
                smap.angle_sign,
                smap.angle_scale,
                smap.servo_index,
            )
            if done is not None:
                self.last_servo_goals, payload = done
                self._publish_payload("servo/target_states", payload)
                return
        q = arr.tolist()
        if vectoring is not None:
            alpha, beta = vectoring
            for i, (ja, jb) in enumerate(self.control.vectoring_joints):
                q[ja], q[jb] = float(alpha[i]), float(beta[i])
        n = min(smap.n_joints, len(q))
        self.last_servo_goals = q if n == len(q) else q[:n]
        self._publish(
            "servo/target_states",
            self._msg["servo/target_states"].new(
                index=list(smap.servo_index[:n]),
                angles=[smap.to_raw(j, q[j]) for j in range(n)],
            ),
        )
