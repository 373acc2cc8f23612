"""The operator layer of the onboard node: take-off, go-to, approach and perch, unperch,
land, halt and the descent of a force landing, as setpoints for the 40 Hz position controller
(sans-IO, time passed in).

What it decides each tick (:meth:`FlightSupervisor.update`):

* the setpoint (position, velocity, yaw) while a take-off, go-to or landing runs: a
  jerk-limited trajectory from ruckig (velocity, acceleration and jerk limits from
  :class:`FlightLimits`), or the plain setpoint a script set with ``OnboardNode.set_target``;
* whether ``four_axes/command`` may go out this tick;
* when to disarm (touchdown).

Modes (:class:`FlightMode`):

=============  =============================================================================
``ground``     disarmed, or armed and not yet flying (nothing commanded by this layer)
``manual``     armed; the setpoint is the script's (``set_target``, the scenarios)
``takeoff``    climbing to the take-off height above the ground z at arming; ``hover``
               after the position stayed within ``takeoff_z_tol`` / ``takeoff_xy_tol`` of the
               target for ``hover_convergent_s`` (JSK's convergence check, sec. 3 of
               ``jsk-flight-navigation.md``)
``hover``      holding, or flying a go-to trajectory
``approach``   the z setpoint rising at ``approach_speed`` (the paper's perching approach,
               Sec. VII-B) until the node reports contact (:meth:`FlightSupervisor.contact`:
               the foot sensor's normal force above ``contact_fz``); back to ``hover`` at the
               start point when it rose ``approach_rise_max`` without contact
``perched``    the setpoint frozen at the contact height (+ ``press_offset``); the node runs
               the perching control (eq. 20's λ_perch) and its gains
``unperch``    perching control off, a jerk-limited path ``unperch_drop`` down; then ``hover``
``land``       z setpoint descending at ``land_descend_rate`` (JSK ``land_descend_vel``,
               0.3 m/s) to ``land_undershoot`` below the ground z; touchdown then disarm
=============  =============================================================================

Touchdown (JSK sec. 4, made safer): every ``land_check_s`` the z is compared with the z of the
previous check; touchdown when it moved less than ``land_pos_tol`` and the vertical velocity is
above ``-land_vel_tol`` **and** the descending setpoint is already within
``touchdown_height`` of the ground z (JSK's check alone disarms a robot that holds its height
in mid-air for 0.5 s). Without position feedback (force landing after mocap loss) the IMU
decides: a level, still robot (gyro below ``still_gyro``, specific force within
``still_acc_tol`` of g) for ``still_s``, not perched.
"""

from __future__ import annotations

import enum
import math
from collections import Counter
from dataclasses import dataclass

import numpy as np
from ruckig import ControlInterface, InputParameter, Result, Ruckig, Trajectory


class FlightMode(enum.Enum):
    GROUND = "ground"
    MANUAL = "manual"
    TAKEOFF = "takeoff"
    HOVER = "hover"
    APPROACH = "approach"
    PERCHED = "perched"
    UNPERCH = "unperch"
    LAND = "land"


@dataclass(frozen=True)
class FlightLimits:
    """Limits and thresholds of the operator layer. JSK's values where it has them
    (``jsk-flight-navigation.md`` sec. 2.4); every other one is an ASSUMPTION."""

    #: Take-off height above the ground z at arming, m (JSK: an absolute height, 0.6-1.2 m).
    takeoff_height: float = 1.0
    #: Take-off is refused when the IMU's roll or pitch at rest is beyond this, rad, or when
    #: no ``imu`` message came within ``takeoff_imu_max_age``, s. A robot resting tilted (on a
    #: line of contacts, a leg on an object) would spend its first thrust rolling over. JSK's
    #: take-off has no such check. ASSUMPTION: 10 deg, and an attitude at most 0.5 s old.
    takeoff_max_tilt: float = 0.175
    takeoff_imu_max_age: float = 0.5
    takeoff_z_tol: float = 0.05
    takeoff_xy_tol: float = 0.15
    hover_convergent_s: float = 1.0
    #: Trajectory limits per axis x, y, z (m/s, m/s^2, m/s^3) and yaw (rad/s, rad/s^2, rad/s^3).
    #: ASSUMPTION: JSK's trajectory mean velocity 0.5 m/s and yaw rate 0.3 rad/s as maxima.
    max_velocity: tuple[float, float, float, float] = (0.5, 0.5, 0.3, 0.3)
    max_acceleration: tuple[float, float, float, float] = (0.5, 0.5, 0.5, 0.5)
    max_jerk: tuple[float, float, float, float] = (2.0, 2.0, 2.0, 2.0)
    #: Landing descent rate, m/s (JSK ``land_descend_vel`` -0.3).
    land_descend_rate: float = 0.3
    #: The descent aims this far below the ground z so the thrust leaves the floor. ASSUMPTION.
    land_undershoot: float = 0.1
    land_check_s: float = 0.5
    land_pos_tol: float = 0.02
    land_vel_tol: float = 0.05
    #: Touchdown only once the setpoint is within this of the ground z. ASSUMPTION.
    touchdown_height: float = 0.1
    #: IMU touchdown (no position feedback). ASSUMPTION.
    still_gyro: float = 0.1
    still_acc_tol: float = 0.8
    still_s: float = 1.0
    #: The longest a command is re-sent unchanged when the pipeline gives none, s.
    command_hold_s: float = 0.1
    #: Roll/pitch targets saturate here, rad (below Spinal's 1.0 rad tilt fail-safe).
    max_tilt_cmd: float = 0.5
    #: Geofence: the position setpoints of take-off and go-to must lie inside, and a measured
    #: position outside lands the robot. ASSUMPTION: a 20 m x 20 m x 4 m room.
    fence_min: tuple[float, float, float] = (-10.0, -10.0, -0.5)
    fence_max: tuple[float, float, float] = (10.0, 10.0, 3.5)
    #: Perching approach: rise rate of the z setpoint, m/s (the paper's slow approach;
    #: ASSUMPTION: 0.08 m/s, the perching scenario's), and how far it may rise without
    #: contact before it gives up, m. ASSUMPTION.
    approach_speed: float = 0.08
    approach_rise_max: float = 1.0
    #: Foot-sensor normal force that means contact, N. ASSUMPTION.
    contact_fz: float = 3.0
    #: How long the foot sensor's fresh normal force must stay above ``contact_fz`` (every
    #: approach tick) before the approach switches to perched, s (>= 0; 0: the first reading
    #: above it). A single noisy reading then does not start the perch with the altitude loop
    #: held away from the ceiling (docs/scenarios.md "perching"). ASSUMPTION.
    contact_hold_s: float = 0.0
    #: Altitude setpoint above the contact height once perched, m (>= 0). ASSUMPTION.
    press_offset: float = 0.0
    #: Position-gain profile switched in at contact (``OnboardConfig.gain_profiles``,
    #: "default": ``position_gains``).
    perched_gains: str = "default"
    #: Unperch: the path goes this far down from the perched setpoint, m. ASSUMPTION.
    unperch_drop: float = 0.15
    #: Joint motions (``rdm ctl joints``): per-joint limits of the jerk-limited path, rad/s,
    #: rad/s^2, rad/s^3. ASSUMPTION: well inside the servos' 5.8 rad/s no-load speed.
    joint_max_velocity: float = 0.5
    joint_max_acceleration: float = 1.0
    joint_max_jerk: float = 5.0

    def __post_init__(self) -> None:
        for name in (
            "takeoff_height",
            "takeoff_max_tilt",
            "takeoff_imu_max_age",
            "takeoff_z_tol",
            "takeoff_xy_tol",
            "hover_convergent_s",
            "land_descend_rate",
            "land_check_s",
            "land_pos_tol",
            "land_vel_tol",
            "touchdown_height",
            "still_gyro",
            "still_acc_tol",
            "still_s",
            "command_hold_s",
            "max_tilt_cmd",
            "approach_speed",
            "approach_rise_max",
            "contact_fz",
            "unperch_drop",
            "joint_max_velocity",
            "joint_max_acceleration",
            "joint_max_jerk",
        ):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"FlightLimits.{name}={v!r} must be finite and > 0")
        if not (math.isfinite(self.land_undershoot) and self.land_undershoot >= 0):
            raise ValueError(f"FlightLimits.land_undershoot={self.land_undershoot!r} must be >= 0")
        if not (math.isfinite(self.contact_hold_s) and self.contact_hold_s >= 0):
            raise ValueError(f"FlightLimits.contact_hold_s={self.contact_hold_s!r} must be >= 0")
        if not (math.isfinite(self.press_offset) and self.press_offset >= 0):
            raise ValueError(f"FlightLimits.press_offset={self.press_offset!r} must be >= 0")
        if self.approach_speed > self.max_velocity[2]:
            raise ValueError("FlightLimits.approach_speed must not exceed max_velocity's z")
        if self.takeoff_max_tilt >= 1.0:
            raise ValueError(
                "FlightLimits.takeoff_max_tilt must be below Spinal's 1.0 rad fail-safe"
            )
        if self.max_tilt_cmd >= 1.0:
            raise ValueError("FlightLimits.max_tilt_cmd must be below Spinal's 1.0 rad fail-safe")
        for name in ("max_velocity", "max_acceleration", "max_jerk"):
            v = getattr(self, name)
            if len(v) != 4 or not all(math.isfinite(x) and x > 0 for x in v):
                raise ValueError(f"FlightLimits.{name} needs 4 finite values > 0")
        for name in ("fence_min", "fence_max"):
            if len(getattr(self, name)) != 3:
                raise ValueError(f"FlightLimits.{name} needs 3 values")
        if not all(lo < hi for lo, hi in zip(self.fence_min, self.fence_max, strict=True)):
            raise ValueError("FlightLimits: fence_min must be below fence_max on every axis")

    def inside_fence(self, p: np.ndarray) -> bool:
        """Whether a world position lies inside the geofence."""
        return all(
            lo <= float(v) <= hi
            for lo, v, hi in zip(self.fence_min, p, self.fence_max, strict=True)
        )


def wrap_angle(a: float) -> float:
    """``a`` in [-pi, pi)."""
    return (a + math.pi) % (2.0 * math.pi) - math.pi


#: Sampling step of a planned path, s: the node keeps the samples (no ruckig object outlives
#: the planning call) and interpolates them linearly between.
PATH_SAMPLE_S = 0.005


class _Path:
    """A ruckig trajectory of x, y, z, yaw from a start time, sampled every
    :data:`PATH_SAMPLE_S` (positions and velocities) and interpolated between samples."""

    def __init__(self, start: float, trajectory: Trajectory) -> None:
        self.start = start
        self.duration = float(trajectory.duration)
        n = max(2, math.ceil(self.duration / PATH_SAMPLE_S) + 1)
        self.times = np.linspace(0.0, self.duration, n)
        samples = [trajectory.at_time(float(t)) for t in self.times]
        self.pos = np.array([s[0] for s in samples])
        self.vel = np.array([s[1] for s in samples])
        self.acc = np.array([s[2] for s in samples])

    @property
    def end(self) -> float:
        return self.start + self.duration

    def state(self, now: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Position, velocity and acceleration (x, y, z, yaw) at ``now``, interpolated."""
        t = min(max(now - self.start, 0.0), self.duration)
        i = min(int(np.searchsorted(self.times, t, side="right")), len(self.times) - 1)
        t0, t1 = self.times[i - 1], self.times[i]
        w = 0.0 if t1 <= t0 else (t - t0) / (t1 - t0)
        return tuple(  # type: ignore[return-value]
            (1.0 - w) * a[i - 1] + w * a[i] for a in (self.pos, self.vel, self.acc)
        )

    def at(self, now: float) -> tuple[np.ndarray, np.ndarray, float]:
        t = min(max(now - self.start, 0.0), self.duration)
        i = min(int(np.searchsorted(self.times, t, side="right")), len(self.times) - 1)
        t0, t1 = self.times[i - 1], self.times[i]
        w = 0.0 if t1 <= t0 else (t - t0) / (t1 - t0)
        pos = (1.0 - w) * self.pos[i - 1] + w * self.pos[i]
        vel = (1.0 - w) * self.vel[i - 1] + w * self.vel[i]
        return pos[:3], vel[:3], wrap_angle(float(pos[3]))


def plan_path(
    limits: FlightLimits,
    start: float,
    position: np.ndarray,
    velocity: np.ndarray,
    yaw: float,
    target: np.ndarray,
    target_yaw: float,
    max_velocity: tuple[float, float, float, float] | None = None,
) -> _Path | None:
    """A time-optimal jerk-limited trajectory (ruckig) from a state at rest in acceleration to
    ``target`` at rest; yaw takes the short way round. None if ruckig refuses."""
    inp = InputParameter(4)
    inp.current_position = [*map(float, position), yaw]
    inp.current_velocity = [*map(float, velocity), 0.0]
    inp.current_acceleration = [0.0] * 4
    inp.target_position = [*map(float, target), yaw + wrap_angle(target_yaw - yaw)]
    inp.target_velocity = [0.0] * 4
    inp.target_acceleration = [0.0] * 4
    inp.max_velocity = list(max_velocity or limits.max_velocity)
    inp.max_acceleration = list(limits.max_acceleration)
    inp.max_jerk = list(limits.max_jerk)
    trajectory = Trajectory(4)
    result = Ruckig(4).calculate(inp, trajectory)
    if result not in (Result.Working, Result.Finished):
        return None
    return _Path(start, trajectory)


def plan_stop(limits: FlightLimits, now: float, path: _Path) -> _Path | None:
    """A jerk-limited stop (ruckig's velocity interface: to zero velocity and acceleration)
    from where ``path`` is at ``now``, within the same limits. None if ruckig refuses."""
    pos, vel, acc = path.state(now)
    inp = InputParameter(4)
    inp.control_interface = ControlInterface.Velocity
    inp.current_position = pos.tolist()
    inp.current_velocity = vel.tolist()
    inp.current_acceleration = acc.tolist()
    inp.target_velocity = [0.0] * 4
    inp.target_acceleration = [0.0] * 4
    inp.max_velocity = list(limits.max_velocity)
    inp.max_acceleration = [
        max(m, abs(float(a))) for m, a in zip(limits.max_acceleration, acc, strict=True)
    ]
    inp.max_jerk = list(limits.max_jerk)
    trajectory = Trajectory(4)
    if Ruckig(4).calculate(inp, trajectory) not in (Result.Working, Result.Finished):
        return None
    return _Path(now, trajectory)


class FlightSupervisor:
    """Operator modes, their setpoints and touchdown (see the module doc). The node calls
    :meth:`update` every control tick with what it knows and applies the result."""

    def __init__(self, limits: FlightLimits) -> None:
        self.limits = limits
        self.mode = FlightMode.GROUND
        self.counts: Counter[str] = Counter()
        self.ground_z: float | None = None
        self.path: _Path | None = None
        self._hold: tuple[np.ndarray, float] | None = None
        self._pending_takeoff: float | None = None
        self._converged_since: float | None = None
        self._check_at: float | None = None
        self._check_z: float | None = None
        self._still_since: float | None = None
        self.touchdown_at: float | None = None
        self._approach: tuple[float, float] | None = None  # (start z, rise rate)
        self._stop: _Path | None = None  # a landing's stop from a path under way
        #: the node time of the last contact (``approach`` -> ``perched``)
        self.perched_at: float | None = None

    # -- operator requests ---------------------------------------------------------------
    def request_takeoff(self, height: float | None) -> str | None:
        """Climb to ``height`` above the ground z once armed; None or the refusal reason."""
        h = self.limits.takeoff_height if height is None else float(height)
        if not (math.isfinite(h) and h > 0.0):
            return "takeoff height must be finite and > 0"
        if self.mode not in (FlightMode.GROUND, FlightMode.MANUAL):
            return f"already in {self.mode.value}"
        self._pending_takeoff = h
        self.counts["takeoff_requested"] += 1
        return None

    def cancel_takeoff(self) -> None:
        """Drop a take-off that waits for arming (arming was refused)."""
        self._pending_takeoff = None

    def request_land(self, now: float) -> str | None:
        """Descend from where the setpoint is at ``now`` (a path under way stops there)."""
        if self.mode is FlightMode.GROUND and self._pending_takeoff is None:
            return "not flying"
        self._pending_takeoff = None
        self._enter_land(now)
        return None

    def request_goto(self, target: np.ndarray, yaw: float, now: float) -> str | None:
        """Fly to ``target`` (world, m) at ``yaw`` along a jerk-limited path."""
        if self.mode is not FlightMode.HOVER:
            return f"goto needs hover (mode {self.mode.value})"
        if not self.limits.inside_fence(target):
            return "target outside the geofence"
        assert self._hold is not None
        p, y = self._setpoint_now(now)
        path = plan_path(self.limits, now, p, np.zeros(3), y, target, yaw)
        if path is None:
            return "no trajectory to the target"
        self.path = path
        self.counts["goto"] += 1
        return None

    def request_approach(
        self, now: float, setpoint: np.ndarray, yaw: float, speed: float | None = None
    ) -> str | None:
        """Start the perching approach from hover (its hold) or from a script's setpoint
        (``setpoint``, ``yaw``): the z setpoint rises at ``speed`` (default
        ``approach_speed``) until :meth:`contact`."""
        rate = self.limits.approach_speed if speed is None else float(speed)
        if not (math.isfinite(rate) and 0.0 < rate <= self.limits.max_velocity[2]):
            return f"approach speed must be in (0, {self.limits.max_velocity[2]}] m/s"
        if self.mode is FlightMode.HOVER:
            if self.path is not None:
                return "a go-to is under way"
            assert self._hold is not None
            start, y = self._hold
        elif self.mode is FlightMode.MANUAL:
            start, y = setpoint, yaw
        else:
            return f"perch needs hover (mode {self.mode.value})"
        self._hold = (np.array(start, dtype=float), float(y))
        self._approach = (float(start[2]), rate)
        self.mode = FlightMode.APPROACH
        self.counts["approach"] += 1
        return None

    def contact(self, now: float, z: float) -> None:
        """The node saw the foot touch (``approach`` only): hold the contact height ``z``
        (measured) plus ``press_offset``; ``perched``."""
        if self.mode is not FlightMode.APPROACH:
            return
        assert self._hold is not None
        p, y = self._hold
        self._hold = (np.array([p[0], p[1], z + self.limits.press_offset]), y)
        self.mode, self._approach, self.perched_at = FlightMode.PERCHED, None, now
        self.counts["contact"] += 1

    def request_unperch(self, now: float) -> str | None:
        """Leave the perch: a jerk-limited path ``unperch_drop`` down from the perched
        setpoint, then ``hover`` (the node switches the perching control off)."""
        if self.mode is not FlightMode.PERCHED:
            return f"not perched (mode {self.mode.value})"
        assert self._hold is not None
        p, y = self._hold
        target = p - np.array([0.0, 0.0, self.limits.unperch_drop])
        path = plan_path(self.limits, now, p, np.zeros(3), y, target, y)
        if path is None:
            return "no trajectory down from the perch"
        self.path, self._hold = path, (target, y)
        self.mode = FlightMode.UNPERCH
        self.counts["unperch"] += 1
        return None

    def manual(self) -> None:
        """A script took the setpoint (``set_target``): this layer stops planning."""
        if self.mode in (FlightMode.TAKEOFF, FlightMode.HOVER):
            self.mode, self.path = FlightMode.MANUAL, None

    def _enter_land(self, now: float) -> None:
        if self.mode is not FlightMode.LAND:
            self.counts["land"] += 1
        self._stop = None
        if self.path is not None:
            # a path under way first comes to a jerk-limited stop; the descent starts there
            # (a setpoint that stood still at once would ask for a step of deceleration)
            self._stop = plan_stop(self.limits, now, self.path)
            if self._stop is None:
                p, _, y = self.path.at(now)
                self._hold = (p, y)
        self.mode = FlightMode.LAND
        self.path, self._approach = None, None
        self._check_at = self._check_z = None
        self._still_since = None

    @property
    def hold_position(self) -> np.ndarray | None:
        """The position this layer holds (hover, perched) or its path ends at; None when it
        commands nothing (ground, manual, before a landing's first tick)."""
        return None if self._hold is None else self._hold[0].copy()

    # -- per tick ------------------------------------------------------------------------
    def _setpoint_now(self, now: float) -> tuple[np.ndarray, float]:
        if self.path is not None:
            p, _, y = self.path.at(now)
            return p, y
        assert self._hold is not None
        return self._hold

    def update(
        self,
        now: float,
        armed: bool,
        force_landing: bool,
        position: np.ndarray | None,
        velocity: np.ndarray | None,
        yaw: float,
        setpoint_position: np.ndarray,
        dt: float,
    ) -> tuple[np.ndarray, np.ndarray, float] | None:
        """The setpoint (position, velocity, yaw) this layer commands now, or None when the
        script's setpoint stands. ``position``/``velocity``: the measured CoG state, None
        without position feedback. ``force_landing``: Spinal is force landing (the layer
        then descends as in ``land``)."""
        if not armed:
            if self.mode is not FlightMode.GROUND:
                self.mode, self.path, self._hold = FlightMode.GROUND, None, None
                self._approach = self._stop = None
            self.ground_z = None
            return None
        if self.ground_z is None and position is not None:
            self.ground_z = float(position[2])
        if force_landing and self.mode is not FlightMode.LAND:
            self._enter_land(now)
        if self.mode is FlightMode.GROUND:
            self.mode = FlightMode.MANUAL
        if self._pending_takeoff is not None and position is not None:
            self._start_takeoff(now, position, yaw)
        if self.mode is FlightMode.MANUAL:
            return None
        if self.mode is FlightMode.LAND:
            return self._land(now, position, velocity, setpoint_position, yaw, dt)
        assert self._hold is not None
        if self.mode is FlightMode.APPROACH:
            return self._rise(now, dt)
        if self.mode is FlightMode.PERCHED:
            return self._hold[0], np.zeros(3), self._hold[1]
        if self.path is not None:
            p, v, y = self.path.at(now)
            if now >= self.path.end:
                self._hold, self.path = (p, y), None
                if self.mode is FlightMode.UNPERCH:
                    self.mode = FlightMode.HOVER
        else:
            (p, y), v = self._hold, np.zeros(3)
        if self.mode is FlightMode.TAKEOFF and position is not None:
            self._takeoff_convergence(now, position)
        return p, v, y

    def _rise(self, now: float, dt: float) -> tuple[np.ndarray, np.ndarray, float]:
        """The approach's rising setpoint; past ``approach_rise_max`` without contact, a
        path back down to where the approach started, in ``hover``."""
        assert self._hold is not None and self._approach is not None
        p, y = self._hold
        z0, rate = self._approach
        z = float(p[2]) + rate * dt
        if z - z0 > self.limits.approach_rise_max:
            self.counts["approach_no_contact"] += 1
            start = np.array([p[0], p[1], z0])
            self.path = plan_path(self.limits, now, p, np.zeros(3), y, start, y)
            self._hold, self._approach = (start, y), None
            self.mode = FlightMode.HOVER
            if self.path is None:  # cannot happen for a straight drop; hold the start
                return start, np.zeros(3), y
            return self.path.at(now)
        self._hold = (np.array([p[0], p[1], z]), y)
        return self._hold[0], np.array([0.0, 0.0, rate]), y

    def _start_takeoff(self, now: float, position: np.ndarray, yaw: float) -> None:
        assert self._pending_takeoff is not None and self.ground_z is not None
        target = np.array([position[0], position[1], self.ground_z + self._pending_takeoff])
        self._pending_takeoff = None
        if not self.limits.inside_fence(target):
            self.counts["takeoff_refused_fence"] += 1
            return
        start = np.array([position[0], position[1], self.ground_z])
        path = plan_path(self.limits, now, start, np.zeros(3), yaw, target, yaw)
        if path is None:
            self.counts["takeoff_no_path"] += 1
            return
        self.path, self._hold = path, (target, yaw)
        self.mode = FlightMode.TAKEOFF
        self._converged_since = None

    def _takeoff_convergence(self, now: float, position: np.ndarray) -> None:
        assert self._hold is not None
        d = self._hold[0] - position  # the take-off target (the path's end)
        inside = (
            abs(float(d[2])) <= self.limits.takeoff_z_tol
            and math.hypot(float(d[0]), float(d[1])) <= self.limits.takeoff_xy_tol
            and self.path is None
        )
        if not inside:
            self._converged_since = None
        elif self._converged_since is None:
            self._converged_since = now
        elif now - self._converged_since >= self.limits.hover_convergent_s - 1e-9:
            self.mode = FlightMode.HOVER
            self.counts["takeoff_converged"] += 1

    def _land(
        self,
        now: float,
        position: np.ndarray | None,
        velocity: np.ndarray | None,
        setpoint_position: np.ndarray,
        yaw: float,
        dt: float,
    ) -> tuple[np.ndarray, np.ndarray, float] | None:
        """The descending setpoint; None without position feedback (nothing to command)."""
        lim = self.limits
        if position is None or velocity is None or self.ground_z is None:
            return None
        if self._stop is not None:  # braking first; the descent starts at the stop
            p, v, y = self._stop.at(now)
            if now < self._stop.end:
                return p, v, y
            self._hold, self._stop = (p, y), None
        if self._hold is None:
            # from a script's setpoint: the measured xy, the lower of the setpoint and the
            # measured z
            z0 = min(float(setpoint_position[2]), float(position[2]))
            self._hold = (np.array([position[0], position[1], z0]), yaw)
        hold, y = self._hold
        floor = self.ground_z - lim.land_undershoot
        z = max(float(hold[2]) - lim.land_descend_rate * dt, floor)
        self._hold = (np.array([hold[0], hold[1], z]), y)
        vz = -lim.land_descend_rate if z > floor else 0.0
        if self._check_at is None or now - self._check_at >= lim.land_check_s - 1e-9:
            z_now = float(position[2])
            if (
                self._check_z is not None
                and abs(z_now - self._check_z) < lim.land_pos_tol
                and float(velocity[2]) > -lim.land_vel_tol
                and z - self.ground_z <= lim.touchdown_height
            ):
                self.touchdown_at = now
                self.counts["touchdown"] += 1
            self._check_at, self._check_z = now, z_now
        return self._hold[0], np.array([0.0, 0.0, vz]), y

    def imu_touchdown(
        self, now: float, gyro: np.ndarray | None, acc: np.ndarray | None, perched: bool
    ) -> bool:
        """Touchdown without position feedback (see the module doc); call while landing."""
        lim = self.limits
        still = (
            not perched
            and gyro is not None
            and acc is not None
            and float(np.linalg.norm(gyro)) < lim.still_gyro
            and abs(float(np.linalg.norm(acc)) - 9.80665) < lim.still_acc_tol
        )
        if not still:
            self._still_since = None
            return False
        if self._still_since is None:
            self._still_since = now
        if now - self._still_since >= lim.still_s - 1e-9:
            self.touchdown_at = now
            self.counts["touchdown_imu"] += 1
            return True
        return False

    def take_touchdown(self) -> bool:
        """Whether a touchdown was detected since the last call (the node then disarms)."""
        if self.touchdown_at is None:
            return False
        self.touchdown_at = None
        return True
