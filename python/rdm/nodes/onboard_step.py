"""The onboard node's control tick: the model update and gain synthesis, the pseudo-inverse
and desired-coordinate messages, the joint targets (held or interpolated on a trajectory), the
mocap state at the tick, the supervision (monitors and their reactions, the operator layer's
setpoint, the approach's contact, touchdown), the flight step and the commands it sends.

:class:`OnboardStep` is a part of :class:`rdm.nodes.onboard.OnboardNode`: its methods read and
write the node's state (``control``, ``flight``, ``monitors``, ``arming`` ...).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from rdm.nodes.onboard_arming import FlightState
from rdm.nodes.onboard_control import ControlCommand, Setpoint, State
from rdm.nodes.onboard_flight import FlightMode
from rdm.nodes.onboard_rotor_loss import diverging_axis, lost_rotor, turning_axis

#: The operator modes in which a lost rotor is watched for (no contact, a flat posture held).
ROTOR_LOSS_MODES = (FlightMode.MANUAL, FlightMode.TAKEOFF, FlightMode.HOVER, FlightMode.LAND)
#: ... a light one (its attitude signs only): not in a landing, whose touchdown tips the
#: body as fast (low-battery and battery-sag landings: 2.6-12 deg off the target at 1.6-1.7
#: rad/s). ASSUMPTION: a light rotor lost while landing is not detected.
LIGHT_ROTOR_LOSS_MODES = (FlightMode.MANUAL, FlightMode.TAKEOFF, FlightMode.HOVER)

try:  # the C function np.interp ends in for float data (without its Python layers)
    from numpy._core.multiarray import interp as _interp
except ImportError:  # another numpy layout: np.interp, the same values

    def _interp(x: float, xp: np.ndarray, fp: np.ndarray, left: None, right: None) -> float:
        return float(np.interp(x, xp, fp, left, right))


class OnboardStep:
    """The control tick of :class:`rdm.nodes.onboard.OnboardNode` (a part of it)."""

    def _control(self, now: float) -> None:
        ctl = self.control
        ctl.update_model(self.present_q)
        ctl.set_perching(self._perch_request)
        if ctl.synthesize_due():
            ok = ctl.synthesize()
            if ctl.gains_wire is not None:  # on failure the last good gains go out again
                self._send_gains()
            if not ok:
                self.counts["gains_kept"] += 1
        pm = ctl.p_matrix_wire()
        if pm is not None:
            self._send_p_matrix(pm)
        if self.config.send_desire_coordinate and ctl.terms is not None:
            cached_desire = self._desire_msg
            if cached_desire is None or cached_desire[0] is not ctl.terms:
                # a function of the model terms alone: rebuilt when they change
                desire = ctl.desire_coordinate()
                assert desire is not None
                roll, pitch, yaw = desire
                msg = self._msg["desire_coordinate"].new(roll=roll, pitch=pitch, yaw=yaw)
                cached_desire = self._desire_msg = (ctl.terms, msg)
            self._publish_same("desire_coordinate", cached_desire[1])
        targets = self._current_joint_targets(now)
        dt = self.period
        if self._last_control is not None:
            measured = now - self._last_control
            if 0 < measured <= 3 * self.period:
                dt = measured
            else:
                self.counts["dt_irregular"] += 1
        self._last_control = now
        self._supervise(now, dt)
        command = None
        if self.arming.flying:
            command = self._flight_step(now, targets, dt)
            if self.rotor_lost_at is not None:
                command = self._fall_command()
        if command is not None:
            self.previous_command = self.last_command
            self.last_command = command
            self.last_alpha_beta = (command.alpha, command.beta)
            self._command_at = now
        if self.arming.flying and self.last_command is not None:
            held = now - (self._command_at if self._command_at is not None else -math.inf)
            if held <= self.config.flight.command_hold_s + 1e-9:
                self._send_command(self.last_command)
            else:  # no fresh command: silence, so that Spinal's timeout and ramp act
                self.counts["command_withheld"] += 1
        if targets is not None:
            lead = self.config.servo_lead_s
            if lead > 0.0 and self._trajectory is not None:
                goals = self._current_joint_targets(now + lead)
                assert goals is not None
                self._send_servo_targets(goals)
            else:
                self._send_servo_targets(targets)

    def _send_p_matrix(self, pm: tuple[list[tuple[int, int, int]], list[int]]) -> None:
        """``p_matrix_pseudo_inverse_inertia`` from the pipeline's wire terms; while a lost
        rotor is arrested its row is zero (no gyro-moment term on a rotor that may come
        back: a reset Neuron's)."""
        lost = self.lost_rotor if self.rotor_lost_at is not None else None
        cached = self._p_matrix_msg
        # the pipeline reuses pm while q holds
        if cached is None or cached[0] is not pm or cached[2] != lost:
            rows, inertia = pm
            if lost is not None:
                rows = [(0, 0, 0) if k == lost else row for k, row in enumerate(rows)]
            unit = self._msg["pinv_unit"]
            msg = self._msg["p_matrix_pseudo_inverse_inertia"].new(
                pseudo_inverse=[unit.new(r=r, p=p, y=y) for r, p, y in rows],
                inertia=inertia,
            )
            cached = self._p_matrix_msg = (pm, msg, lost)
        self._publish_same("p_matrix_pseudo_inverse_inertia", cached[1])

    def _flight_step(
        self, now: float, targets: np.ndarray | None, dt: float
    ) -> ControlCommand | None:
        if not self._mocap_usable(now):
            self.counts["command_held"] += 1
            if self._mocap_lost_since is None:
                self._mocap_lost_since = now
            elif (
                now - self._mocap_lost_since >= self.config.mocap_loss_force_landing_s
                and self.arming.state is FlightState.ARMED
            ):
                self.counts["mocap_lost_force_landing"] += 1
                self.arming.force_landing(now)
            return None
        self._mocap_lost_since = None
        p, v, yaw = self._mocap_at(now)
        self._rp_integration(float(p[2]))
        if yaw is None:
            if self.imu_euler is None:
                self.counts["no_yaw"] += 1
                return None
            yaw = self.imu_euler[2]
        jt = targets if targets is not None else self.present_q
        foot = None if self.foot is None else self.foot.latest(now, self.config.foot_timeout_s)
        setpoint = self._flight_setpoint or self.setpoint
        try:
            return self.control.step(State(p, v, yaw), setpoint, jt, foot, dt)
        except ValueError:
            self.counts["control_error"] += 1
            return None

    def _current_joint_targets(self, now: float) -> np.ndarray | None:
        """The joint targets at ``now``: the trajectory's (linear between its points, held
        after the last) or the held ``joint_targets``."""
        trajectory = self._trajectory
        if trajectory is None:
            return self.joint_targets
        times, qs = trajectory  # float64, one row per time (set_trajectory)
        cached = self._trajectory_columns
        if cached is None or cached[0] is not trajectory:
            columns = tuple(np.ascontiguousarray(qs[:, j]) for j in range(qs.shape[1]))
            cached = self._trajectory_columns = (trajectory, columns)
        return np.array([_interp(now, times, column, None, None) for column in cached[1]])

    def _mocap_usable(self, now: float) -> bool:
        return (
            self._mocap is not None
            and self._mocap_stamp is not None
            and now - self._mocap_stamp <= self.config.mocap_timeout_s + 1e-9
        )

    def _mocap_at(self, now: float) -> tuple[np.ndarray, np.ndarray, float | None]:
        """The usable mocap state at ``now``: a marker pose's CoG position predicted over the
        sample's age with its estimated velocity (constant velocity, the filter's model:
        motion capture's latency compensated), else the sample as given."""
        assert self._mocap is not None and self._mocap_stamp is not None
        p, v, y = self._mocap
        age = now - self._mocap_stamp
        if self._mocap_latent and age > 0.0:
            p = p + v * age
        return p, v, y

    def _supervise(self, now: float, dt: float) -> None:
        """Monitors, the operator layer's setpoint and touchdown (then ARM_OFF)."""
        flying = self.arming.flying
        p = v = None
        yaw = 0.0
        if self._mocap_usable(now):
            p, v, y = self._mocap_at(now)
            euler = self.imu_euler
            yaw = y if y is not None else (euler[2] if euler is not None else 0.0)
        self._monitor(now, flying, p)
        self._rotor_loss(now, flying)
        if self.flight.mode is FlightMode.APPROACH and p is not None:
            self._contact_check(now, float(p[2]))
        else:
            self._contact_since = None
        landing = self.arming.state is FlightState.LANDING
        sp = self.flight.update(now, flying, landing, p, v, yaw, self.setpoint.position, dt)
        self._flight_setpoint = None if sp is None else Setpoint(*sp)
        if self.flight.mode is FlightMode.LAND and self._perch_request:
            # a landing (force landing, a fault) from the perch: perching control off first
            self._perch_request = False
            self.control.set_perching(False)
            self.counts["perch_released_to_land"] += 1
        if flying and self.flight.mode is FlightMode.LAND and p is None:
            self.flight.imu_touchdown(now, self.imu_gyro, self._imu_acc, self.control.perching)
        if self.flight.take_touchdown():
            self.monitors.trip("touchdown", "landed: ARM_OFF", now)
            self.arming.disarm(now)

    def _rotor_loss(self, now: float, flying: bool) -> None:
        """A lost rotor (:mod:`rdm.nodes.onboard_rotor_loss`): detected in flight, Spinal's
        attitude loop, on Table V's LQI gains without the lost rotor's row, stops the turn on
        the thrust floor (:meth:`_fall_command`), then the node disarms (the motors stop)
        and the robot falls."""
        lim = self.config.monitors
        if not flying:
            self.rotor_lost_at = None  # lost_rotor keeps the last detection's rotor
            self.control.use_arrest_gains(False)  # the configured weights for the next flight
            return
        if self.rotor_lost_at is not None:
            # Spinal's 1 kHz attitude loop on the thrust floor stops the turn for
            # ``rotor_loss_arrest_s`` (a light rotor: ``rotor_loss_light_arrest_s``); then
            # the motors stop (ARM_OFF) and the robot falls keeping its attitude
            arrest = lim.rotor_loss_arrest_s if self.lost_heavy else lim.rotor_loss_light_arrest_s
            due = now - self.rotor_lost_at >= arrest - 1e-9
            if due and self.arming.state is not FlightState.DISARMING:
                why = f"{now - self.rotor_lost_at:.3f} s after the detection"
                self.monitors.trip("rotor_lost_cut", f"{why}: ARM_OFF, falling", now)
                self.arming.disarm(now)
                self._arming_messages(now)  # this tick, not the next one's arming step
            return
        found = self._rotor_loss_signs(now)
        if found is None:
            return
        axis, heavy, force = found
        self.lost_heavy = heavy
        euler, gyro = self.imu_euler, self.imu_gyro
        assert euler is not None and gyro is not None
        rates = (float(gyro[0]), float(gyro[1]))
        t = self.control.terms
        self.lost_rotor = (
            None
            if t is None
            else lost_rotor(
                t.allocation_bar,
                t.hover_thrust,
                t.inertia,
                rates,
                heavy,
                t.mass * self.config.gravity,
            )
        )
        self.rotor_lost_at = now
        c = self.last_command
        target = (0.0, 0.0) if c is None else (float(c.angles[0]), float(c.angles[1]))
        i = 0 if axis == "roll" else 1
        self.monitors.trip(
            "rotor_lost",
            f"rotor {self.lost_rotor if self.lost_rotor is not None else '?'} "
            f"({'heavy' if heavy else 'light'}): {axis} "
            f"{math.degrees(float(euler[i]) - target[i]):.1f} deg off its target, "
            f"turning at {rates[i]:.2f} rad/s, specific force {force:.2f} m/s^2: "
            f"its gains off, base thrust to {lim.rotor_loss_fall_thrust} N, then ARM_OFF",
            now,
        )
        self.counts["rotor_lost_fall"] += 1
        # Table V's stiffer roll loop without the lost rotor's row, and its gyro-moment row
        # zero, both sent in this tick
        self.control.use_arrest_gains(True)
        if self.control.gains_wire is not None:
            self._send_gains()
        pm = self.control.p_matrix_wire()
        if pm is not None:
            self._send_p_matrix(pm)
        if self.flight.mode is not FlightMode.LAND:
            self.flight.request_land(now)

    def _rotor_loss_signs(self, now: float) -> tuple[str, bool, float] | None:
        """The tick's lost-rotor signs (module doc of :mod:`rdm.nodes.onboard_rotor_loss`):
        the axis turning, whether the rotor is a heavy one (the specific force dropped) and
        the specific force, m/s^2; None without them or outside the watched flight."""
        lim = self.config.monitors
        euler, gyro, acc = self.imu_euler, self.imu_gyro, self._imu_acc
        if (
            euler is None
            or gyro is None
            or acc is None
            or self.flight.mode not in ROTOR_LOSS_MODES
            or self._trajectory is not None
            or self.control.perching
            # the node flies the robot only while its command is fresh; when it withholds
            # it (motion capture lost), Spinal's timeout and force landing fly it, not the
            # target last sent
            or self._command_at is None
            or now - self._command_at > self.config.flight.command_hold_s + 1e-9
        ):
            return None
        force = math.sqrt(math.fsum(v * v for v in acc))
        if force <= lim.rotor_loss_min_specific_force or not self._off_the_floor():
            return None  # every motor stopped (a fall), not one rotor; or on the floor
        c = self.last_command
        target = (0.0, 0.0) if c is None else (float(c.angles[0]), float(c.angles[1]))
        roll_pitch = (float(euler[0]), float(euler[1]))
        rates = (float(gyro[0]), float(gyro[1]))
        heavy = force < lim.rotor_loss_specific_force
        if heavy:
            axis = diverging_axis(
                lim.rotor_loss_tilt_rad, lim.rotor_loss_rate_rad_s, roll_pitch, target, rates
            ) or turning_axis(lim.rotor_loss_early_rate_rad_s, rates)
        elif (
            force < lim.rotor_loss_light_specific_force
            and self.flight.mode in LIGHT_ROTOR_LOSS_MODES
        ):
            b = self.previous_command
            previous = target if b is None else (float(b.angles[0]), float(b.angles[1]))
            axis = diverging_axis(
                lim.rotor_loss_light_tilt_rad,
                lim.rotor_loss_rate_rad_s,
                roll_pitch,
                target,
                rates,
                previous,
            )
        else:
            axis = None
        return None if axis is None else (axis, heavy, force)

    def _off_the_floor(self) -> bool:
        """Motion capture's height at least ``rp_integration_height`` above the arming
        height (the floor): a foot on the floor tips the body as a lost rotor does (a
        low-battery descent resting on one foot in ``hover``: 12-14 deg off the target at
        1.7-2.0 rad/s, specific force 7.2-7.6 m/s^2). ASSUMPTION: a rotor lost below that
        height is not detected."""
        mocap, floor = self.mocap, self._arm_z
        return (
            mocap is not None
            and floor is not None
            and float(mocap[0][2]) - floor >= self.config.rp_integration_height
        )

    def _fall_command(self) -> ControlCommand | None:
        """The command while a lost rotor's turn is stopped: roll and pitch targets, for a
        heavy rotor, the attitude of the tick (the turn stopped where it is: no error for
        Spinal's loop to turn back, so a rotor that comes back is not driven hard), for a
        light one 0 (the other three can level the robot), no yaw term, every rotor's base
        thrust at ``rotor_loss_fall_thrust`` (Spinal's attitude terms on top), the
        vectoring angles of the last command."""
        c = self.last_command
        if c is None:
            return None
        floor = self.config.monitors.rotor_loss_fall_thrust
        thrust = np.full(np.asarray(c.base_thrust).shape, floor)
        euler = self.imu_euler
        angles = (0.0, 0.0, 0.0)
        if self.lost_heavy and euler is not None:
            angles = (float(euler[0]), float(euler[1]), 0.0)
        return replace(
            c,
            angles=angles,
            base_thrust=thrust,
            flight_thrust=thrust,
            perch_thrust=np.zeros_like(thrust),
            perch=None,
            yaw_rotor=None,
        )

    def _contact_check(self, now: float, z: float) -> None:
        """The approach's contact: the foot sensor's fresh normal force above
        ``FlightLimits.contact_fz`` on every approach tick for ``FlightLimits.contact_hold_s``
        -> perched at the measured height ``z``, the ``perched_gains`` profile now and the
        perching control from the next tick (whose synthesis then sees it first, as for
        :meth:`request_perch`). A reading at or below it, or a tick outside the approach,
        starts the count again."""
        lim = self.config.flight
        wrench = None if self.foot is None else self.foot.latest(now, self.config.foot_timeout_s)
        if wrench is None or not float(wrench[2]) > lim.contact_fz:
            self._contact_since = None
            return
        if self._contact_since is None:
            self._contact_since = now
        if now - self._contact_since < lim.contact_hold_s - 1e-9:
            self.counts["contact_pending"] += 1
            return
        self._contact_since = None
        self.flight.contact(now, z)
        self._perch_request = True  # the next tick's model update and synthesis perch
        if self.gain_profile != lim.perched_gains:
            self.set_gain_profile(lim.perched_gains, bumpless=False)
        self.monitors.note("contact", f"foot F_z {float(wrench[2]):.2f} N: perched", now)

    def _monitor(self, now: float, flying: bool, position: np.ndarray | None) -> None:
        """Freshness of Spinal's imu and the servos, the foot sensor while perched, the
        geofence and the battery; a trip in flight lands, perched it holds."""
        m, lim = self.monitors, self.config.monitors
        if self._link_up_at is not None:
            last = self._imu_at if self._imu_at is not None else self._link_up_at
            silent = now - last > lim.imu_timeout_s + 1e-9
            why = f"no {'plausible ' if m.imu_refusing else ''}imu for {now - last:.3f} s"
            if m.stale("spinal_silent", silent, now, why):
                self._react("spinal_silent", now)
        if flying:
            last = self._servo_at if self._servo_at is not None else self._link_up_at
            stale = last is not None and now - last > lim.servo_timeout_s + 1e-9
            if m.stale("servo_stale", stale, now, "no servo/states"):
                self._react("servo_stale", now)
            if position is not None:
                outside = not self.config.flight.inside_fence(position)
                if m.stale("geofence", outside, now, f"position {position.tolist()} outside"):
                    self._react("geofence", now)
            if m.battery_low(now):
                self._react("battery_low", now)
            if m.battery_sag(now):
                self._react("battery_sag", now)
            t = self.control.terms
            hover = float(np.max(t.hover_thrust)) if t is not None else float("nan")
            if m.battery_reserve(now, hover):
                self._react("battery_reserve", now)
        if self.foot is not None and self.control.perching:
            missing = self.foot.latest(now, self.config.foot_timeout_s) is None
            m.stale("foot_stale", missing, now, "no foot-sensor sample while perched")
        self._monitor_joints(now)
        self._monitor_perch_qp(now)

    def _monitor_joints(self, now: float) -> None:
        """Joint tracking: the goals last sent against the present angles (``servo/states``);
        on a trip the joints are held where they are (the trajectory dropped) and the node
        reacts as to any fault (in flight land, perched hold)."""
        goals = self.last_servo_goals
        if goals is None:
            return
        lim = self.config.monitors
        n = min(len(goals), self.present_q.size)
        err = np.abs(np.asarray(goals[:n], dtype=float) - self.present_q[:n])
        worst = int(np.argmax(err)) if n else 0
        off = bool(n) and float(err[worst]) > lim.joint_tracking_rad
        reason = f"joint {worst} {float(err[worst]) if n else 0.0:.3f} rad from its goal"
        if self.monitors.sustained("joint_tracking", off, lim.joint_tracking_s, now, reason):
            self._trajectory = None
            if self._hold_joints(self.present_q):
                self.counts["joints_held"] += 1
            self._react("joint_tracking", now)

    def _monitor_perch_qp(self, now: float) -> None:
        """Perching QP status: every perched tick without a solution (the controller's safe
        command) for ``perch_qp_fail_s`` trips ``perch_qp_failed`` (perched: hold)."""
        c, at = self.last_command, self._command_at  # the previous control tick's
        failed = (
            self.control.perching
            and c is not None
            and c.perch is not None
            and at is not None
            and now - at <= 1.5 * self.period + 1e-9
            and not c.perch.ok
        )
        status = "-" if c is None or c.perch is None else c.perch.status
        lim = self.config.monitors
        if self.monitors.sustained(
            "perch_qp_failed", failed, lim.perch_qp_fail_s, now, f"perching QP {status}"
        ):
            self._react("perch_qp_failed", now)

    def _react(self, monitor: str, now: float) -> None:
        """A fault's reaction: in flight land; perched hold (or land when configured)."""
        if not self.arming.flying:
            return
        if self.control.perching:
            if monitor == "ground_lost" and self.config.monitors.ground_loss_perched == "land":
                self._perch_request = False
            else:
                self.counts[f"{monitor}_hold"] += 1
                return
        if self.flight.mode is not FlightMode.LAND:
            self.flight.request_land(now)
            self.counts[f"{monitor}_land"] += 1
