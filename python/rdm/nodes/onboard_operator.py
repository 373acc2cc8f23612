"""The onboard node's inputs from outside and its operator layer: mocap samples and poses,
position and joint targets, joint trajectories and motions, perch and unperch, arm, disarm,
force landing, take-off, landing, halt, go-to, gain profiles, the ground link's loss. Every
input is validated (finite vectors of the right length); a bad one is counted and ignored.

:class:`OnboardOperator` is a part of :class:`rdm.nodes.onboard.OnboardNode`: its methods read
and write the node's state (``setpoint``, ``joint_targets``, ``flight``, ``monitors`` ...).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from rdm._rdm import finite_float_vector as _finite_float_vector
from rdm.nodes.joint_motion import plan_joint_motion
from rdm.nodes.onboard_arming import FlightState
from rdm.nodes.onboard_control import Setpoint
from rdm.nodes.onboard_flight import FlightMode
from rdm.nodes.onboard_monitors import LOG

_F64 = np.dtype(np.float64)

#: A joint goal this far past a limit [rad] is still taken (:meth:`OnboardOperator.
#: _joint_limit_refusal`). ASSUMPTION: 1e-5 rad, far below a servo tick (~1e-3 rad): the
#: shipped URDF writes the arm's limits as pi/2 to 11 decimals (1.57079632679) and the
#: scenarios' postures as pi/2 to 5 decimals (1.5708, 3.7e-6 rad further), the same servo goal.
JOINT_LIMIT_SLACK = 1e-5


def _vector(value: Any, n: int) -> np.ndarray | None:
    """``value`` as a finite float vector of length n, else None: a list or tuple of n exact
    floats (a decoded message field) in one Rust call, a float64 vector as it is, anything
    else through numpy."""
    got = _finite_float_vector(value, n)  # None: not that form; False: a value not finite
    if got is not None:
        return None if got is False else got
    if type(value) is np.ndarray and value.dtype == _F64 and value.shape == (n,):
        # a float vector already (a script's setpoint): the view numpy's reading below gives,
        # its values checked as Python floats (np.isfinite's dispatch costs more)
        return value.reshape(-1) if all(map(math.isfinite, value.tolist())) else None
    try:
        v = np.asarray(value, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        return None
    if v.shape != (n,) or not np.all(np.isfinite(v)):
        return None
    return v


def _scalar(value: Any) -> float | None:
    try:
        v = float(value)
    except (TypeError, ValueError):
        return None
    return v if math.isfinite(v) else None


class OnboardOperator:
    """The inputs and operator commands of :class:`rdm.nodes.onboard.OnboardNode` (a part of it)."""

    #: the model's joint limits, read on first use (:meth:`_joint_limits`)
    _joint_limits_cache: tuple[np.ndarray, np.ndarray] | None = None

    def set_mocap(
        self, position: Sequence[float], velocity: Sequence[float], yaw: float | None = None
    ) -> bool:
        """Motion-capture (or ground-truth) world position/velocity of the controlled point
        and optionally yaw [rad]; stamped with the node's current time. Invalid -> counted,
        ignored (the last command is held)."""
        p, v = _vector(position, 3), _vector(velocity, 3)
        y = None if yaw is None else _scalar(yaw)
        if p is None or v is None or (yaw is not None and y is None):
            self.counts["mocap_invalid"] += 1
            return False
        self._mocap = (p, v, y)
        self._mocap_stamp = self._now
        self._mocap_latent = False
        return True

    def set_mocap_pose(
        self, position: Sequence[float], quaternion: Sequence[float], stamp: float | None = None
    ) -> bool:
        """A motion-capture sample as the system gives it: the world pose of the marker body
        on the root link (position [m], quaternion x, y, z, w) taken at ``stamp`` (node time;
        default: now). The CoG state comes from :class:`rdm.nodes.onboard_mocap.CogEstimator`
        at the present joint angles. Invalid (non-finite, not a unit quaternion within 1 %,
        a stamp more than 0.1 s ahead of the node) -> counted, ignored."""
        p, quat = _vector(position, 3), _vector(quaternion, 4)
        st = self._now if stamp is None else _scalar(stamp)
        norm = 0.0 if quat is None else float(np.linalg.norm(quat))
        if (
            p is None
            or quat is None
            or st is None
            or abs(norm - 1.0) > 0.01
            or st > self._now + 0.1
        ):
            self.counts["mocap_invalid"] += 1
            return False
        cog, velocity, yaw = self.cog_estimator.update(st, p, quat / norm, self.present_q)
        self._mocap = (cog, velocity, yaw)
        self._mocap_stamp = st
        self._mocap_latent = True
        return True

    def set_target(
        self,
        position: Sequence[float],
        yaw: float = 0.0,
        velocity: Sequence[float] | None = None,
    ) -> bool:
        """World target position [m], yaw [rad], optional velocity [m/s]."""
        p = _vector(position, 3)
        v = np.zeros(3) if velocity is None else _vector(velocity, 3)
        y = _scalar(yaw)
        if p is None or v is None or y is None:
            self.counts["target_invalid"] += 1
            return False
        self.setpoint = Setpoint(p, v, y)
        self.flight.manual()
        return True

    def set_joint_targets(self, q: Sequence[float]) -> bool:
        """Joint targets: q1..q6 (vectoring targets kept) or the full joint_order vector,
        finite (else counted ``joint_targets_invalid`` and ignored) and inside the model's
        joint limits (:meth:`_joint_limit_refusal`)."""
        n_q = self.robot.n_q
        arr = _vector(q, 6 if np.size(q) == 6 else n_q)
        if arr is None:
            self.counts["joint_targets_invalid"] += 1
            return False
        if self._joint_limit_refusal(arr, "set_joint_targets") is not None:
            return False
        base = self.joint_targets if self.joint_targets is not None else self.present_q.copy()
        base = base.copy()
        base[: arr.size] = arr
        self.joint_targets = base
        self._trajectory = None
        return True

    def _joint_limit_refusal(self, q: np.ndarray, path: str) -> str | None:
        """The joint-limit check of every joint command path (:meth:`set_joint_targets`,
        :meth:`set_trajectory`, :meth:`move_joints`, the joint hold): ``q`` (one vector or one
        row per point; the first columns of joint_order) inside the model's joint limits (the
        limits and :data:`JOINT_LIMIT_SLACK` past them included). Else the refusal naming the
        first joint outside, its value and the limit, logged as one line and counted
        ``joint_targets_invalid``; None when inside. A value that is not finite is outside."""
        lo, hi = self._joint_limits()
        rows = np.atleast_2d(np.asarray(q, dtype=float))
        n = rows.shape[1]
        outside = ~((rows >= lo[:n] - JOINT_LIMIT_SLACK) & (rows <= hi[:n] + JOINT_LIMIT_SLACK))
        if not outside.any():
            return None
        k, j = (int(i) for i in np.argwhere(outside)[0])
        v = float(rows[k, j])
        if v < lo[j]:
            rule = f"below its lower limit {float(lo[j])!r}"
        elif v > hi[j]:
            rule = f"above its upper limit {float(hi[j])!r}"
        else:
            rule = "not finite"
        reason = f"joint {self.robot.joint_names[j]} = {v!r} rad {rule} rad"
        self.counts["joint_targets_invalid"] += 1
        LOG.warning("%s refused: %s", path, reason)
        return reason

    def _joint_limits(self) -> tuple[np.ndarray, np.ndarray]:
        """The model's joint limits (lower, upper) [rad], in joint order (read once)."""
        if self._joint_limits_cache is None:
            lo, hi = np.asarray(self.robot.joint_limits, dtype=float).T
            self._joint_limits_cache = (lo.copy(), hi.copy())
        return self._joint_limits_cache

    def _hold_joints(self, q: np.ndarray) -> bool:
        """Hold the joints at ``q`` (the present angles): clamped to the model's joint limits
        (a reading outside them, inside the wire's range, counted ``joint_hold_clamped``),
        then through :meth:`set_joint_targets`' checks. False (nothing held) when refused."""
        lo, hi = self._joint_limits()
        q = np.asarray(q, dtype=float)
        n = min(q.size, lo.size)
        held = np.clip(q[:n], lo[:n], hi[:n])
        if not np.array_equal(held, q[:n]):
            self.counts["joint_hold_clamped"] += 1
        return self.set_joint_targets(held)

    def set_trajectory(self, points: Sequence[tuple[float, Sequence[float]]]) -> bool:
        """Planner output: (node time [s], full joint_order q) pairs, strictly increasing
        times, every point inside the model's joint limits (:meth:`_joint_limit_refusal`;
        the linear interpolation between them stays inside); targets are interpolated
        linearly and held after the last point. False (the trajectory kept) when refused."""
        try:
            times = np.array([float(t) for t, _ in points])
            qs = np.array([np.asarray(q, dtype=float).reshape(-1) for _, q in points])
        except (TypeError, ValueError):
            self.counts["trajectory_invalid"] += 1
            return False
        if (
            times.size == 0
            or qs.shape != (times.size, self.robot.n_q)
            or not (np.all(np.isfinite(times)) and np.all(np.isfinite(qs)))
            or np.any(np.diff(times) <= 0)
        ):
            self.counts["trajectory_invalid"] += 1
            return False
        if self._joint_limit_refusal(qs, "set_trajectory") is not None:
            return False
        self._trajectory = (times, qs)
        return True

    def move_joints(self, q: Sequence[float]) -> str | None:
        """Move the joints to ``q`` (q1..q6, vectoring targets kept, or the full joint_order
        vector) along a jerk-limited path (:mod:`rdm.nodes.joint_motion`, limits
        ``FlightLimits.joint_max_*``) from the present targets; the goal inside the model's
        joint limits (:meth:`_joint_limit_refusal`). The refusal reason or None."""
        n_q = self.robot.n_q
        arr = _vector(q, 6 if np.size(q) == 6 else n_q)
        if arr is None:
            self.counts["joint_targets_invalid"] += 1
            return f"q must be 6 or {n_q} finite numbers"
        start = self._current_joint_targets(self._now)
        start = (self.present_q if start is None else start).copy()
        goal = start.copy()
        goal[: arr.size] = arr
        refusal = self._joint_limit_refusal(goal, "move_joints")
        if refusal is not None:
            return refusal
        lim = self.config.flight
        points = plan_joint_motion(
            self._now,
            start,
            goal,
            lim.joint_max_velocity,
            lim.joint_max_acceleration,
            lim.joint_max_jerk,
        )
        if points is None or not self.set_trajectory(points):
            return "no joint trajectory to the goal"
        self.counts["joint_motion"] += 1
        return None

    def request_perch(self, on: bool = True) -> None:
        """Switch between flight mode and perching mode (eq. 20's λ_perch on/off) at once,
        without the perch sequence (:meth:`perch`, :meth:`unperch`)."""
        self._perch_request = bool(on)

    def perch(self, speed: float | None = None) -> str | None:
        """The perch sequence: approach (the z setpoint rising at ``speed``, default
        ``FlightLimits.approach_speed``) until the foot sensor reads more than
        ``FlightLimits.contact_fz``, then the perching control (eq. 20) and the
        ``perched_gains`` profile at the contact height. The refusal reason or None."""
        if self.foot is None:
            return "no foot sensor"
        if not self.arming.flying:
            return "not flying"
        profile = self.config.flight.perched_gains
        if profile != "default" and profile not in self.config.gain_profiles:
            return f"FlightLimits.perched_gains names no gain profile ({profile!r})"
        sp = self.setpoint
        return self.flight.request_approach(self._now, sp.position, sp.yaw, speed)

    def unperch(self) -> str | None:
        """Leave the perch: perching control off, a jerk-limited path down, then hover."""
        reason = self.flight.request_unperch(self._now)
        if reason is None:
            self._perch_request = False
        return reason

    def arm(self) -> str | None:
        """Start the arming sequence; the refusal reason (battery) or None."""
        t = self.control.terms
        hover = float(np.max(t.hover_thrust)) if t is not None else math.nan
        refusal = self.monitors.arm_refusal(hover)
        if refusal is not None:
            self.monitors.trip("arm_refused", refusal, self._now)
            return refusal
        self._requests.append("arm")
        return None

    def disarm(self) -> None:
        """ARM_OFF (the motors stop at once)."""
        self._requests.append("disarm")

    def force_landing(self) -> None:
        """FORCE_LANDING to Spinal; the node then descends under position control while it
        has position feedback, else stays silent so that Spinal's own ramp acts."""
        self._requests.append("force_landing")

    # ------------------------------------------------------------------ operator layer
    def takeoff(self, height: float | None = None) -> str | None:
        """Arm if needed, then climb ``height`` m (default ``FlightLimits.takeoff_height``)
        above the ground z at arming; the refusal reason or None."""
        idle = self.arming.state in (FlightState.IDLE, FlightState.DISARMING)
        if idle and self.flight.mode is FlightMode.GROUND:
            refusal = self._takeoff_attitude_refusal()
            if refusal is not None:
                self.monitors.trip("takeoff_refused_tilt", refusal, self._now)
                return refusal
        reason = self.flight.request_takeoff(height)
        if reason is None and idle:
            reason = self.arm()
            if reason is not None:
                self.flight.cancel_takeoff()
        return reason

    def _takeoff_attitude_refusal(self) -> str | None:
        """Why the robot may not take off from its resting attitude (None: it may): no fresh
        ``imu`` message, or roll/pitch beyond ``FlightLimits.takeoff_max_tilt``."""
        limits = self.flight.limits
        euler = self.imu_euler
        if euler is None or self._imu_at is None:
            return "no attitude from Spinal yet (no imu message)"
        age = self._now - self._imu_at
        if age > limits.takeoff_imu_max_age:
            return (
                f"attitude {age:.2f} s old (> takeoff_imu_max_age {limits.takeoff_imu_max_age} s)"
            )
        roll, pitch = euler[0], euler[1]
        # The tilt of the body z axis from vertical (ZYX Euler: cos tilt = cos roll cos pitch).
        tilt = math.acos(max(-1.0, min(1.0, math.cos(roll) * math.cos(pitch))))
        if not math.isfinite(tilt) or tilt > limits.takeoff_max_tilt:
            return (
                f"resting tilt {math.degrees(tilt):.1f} deg (roll {math.degrees(roll):.1f}, "
                f"pitch {math.degrees(pitch):.1f}) beyond takeoff_max_tilt "
                f"{math.degrees(limits.takeoff_max_tilt):.1f} deg"
            )
        return None

    def land(self) -> str | None:
        """Descend at ``FlightLimits.land_descend_rate``, detect touchdown, disarm."""
        if self.control.perching:
            return "perched: unperch first"
        return self.flight.request_land(self._now)

    def halt(self) -> None:
        """ARM_OFF from any state (JSK ``halt``): the motors stop where the robot is."""
        self.counts["halt"] += 1
        self._requests.append("disarm")

    def goto(self, position: Sequence[float], yaw: float = 0.0) -> str | None:
        """Fly to a world position [m] and yaw [rad] along a jerk-limited path (hover only)."""
        p, y = _vector(position, 3), _scalar(yaw)
        if p is None or y is None:
            self.counts["goto_invalid"] += 1
            return "position must be 3 finite numbers and yaw finite"
        return self.flight.request_goto(p, y, self._now)

    def set_gain_profile(self, name: str, bumpless: bool = True) -> str | None:
        """Switch the position gains to a named profile of ``OnboardConfig.gain_profiles``
        ("default": ``position_gains``), bumplessly unless told otherwise."""
        profiles = {"default": self.config.position_gains, **self.config.gain_profiles}
        if name not in profiles:
            return f"unknown gain profile {name!r}; known: {sorted(profiles)}"
        self.use_position_gains(profiles[name], name, bumpless)
        return None

    def use_position_gains(self, gains: dict, name: str, bumpless: bool = False) -> None:
        """Position gains (``OnboardConfig.position_gains`` keys) under a profile ``name``: a
        script's gain schedule outside the configured profiles. The perch contact switches
        back to ``FlightLimits.perched_gains`` when ``name`` differs from it."""
        self.control.set_position_gains(dict(gains), bumpless=bumpless)
        self.gain_profile = name

    def on_ground_lost(self) -> None:
        """The ground station fell silent: land in flight; perched, hold (or land, as
        ``MonitorLimits.ground_loss_perched`` says)."""
        self.ground_lost = True
        self.monitors.trip("ground_lost", "no ground heartbeat", self._now)
        self._react("ground_lost", self._now)

    def on_ground_restored(self) -> None:
        """The ground station is back (a landing it caused goes on)."""
        self.ground_lost = False
        self.counts["ground_restored"] += 1
