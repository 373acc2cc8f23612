"""Health monitors of the onboard node: battery, input freshness (Spinal's ``imu``, the
servos' ``servo/states``, the foot sensor, the ground station), the geofence and the commanded
tilt. Each trip is counted under its monitor's name, logged (``logging`` logger
``rdm.onboard``, warning) and kept in a short list of events for the status line; the node
decides the reaction (``docs/flying.md`` "What the robot does on each fault").

Battery (``jsk-flight-navigation.md`` sec. 8, made stricter): the cell count comes from the
configuration or, by default, from the highest reference voltage of ``motor_info``
(``round(V / 4.2)``: the Hydrus example's 25.2 V is 6S). A reading outside
``cell_plausible`` x cells is rejected, counted (``battery_implausible``) and the last good
value kept. A plausible reading below ``cell_low`` x cells for ``low_battery_s`` trips
``battery_low`` (the node lands). Arming is refused without a plausible reading at or above
``cell_arm_min`` x cells once one has arrived. JSK instead maps a sag-compensated voltage onto
a Li-Po percentage; a per-cell threshold on Spinal's filtered voltage is the ASSUMPTION here.

Battery sag (``battery_sag``, the node lands): Spinal low-passes its reading (0.99/0.01 every
20 ms, a 2 s time constant, jsk-flight-navigation.md sec. 8), so a pack falling 1 V/s reads
2 V high and crosses ``cell_low`` seconds after the thrust has given out (the duty to
thrust map goes with V^2). The node undoes the filter: from a reading ``y`` and the newest
one ``y0`` at least ``PACK_SPAN_S`` older (``dt`` apart), ``a = 0.99^(dt / 0.02)`` and the
pack voltage over that span is ``(y - a y0) / (1 - a)`` (:func:`pack_voltage`). A pack
voltage more than ``cell_sag_v`` x cells below its highest of the last ``sag_window_s``
trips ``battery_sag``. ASSUMPTION: the thresholds (:class:`MonitorLimits`); a load step
(take-off, a climb) sags the pack by the pack's resistance times the current step, below
the threshold (JSK's hover sag compensation: 0.05 ohm x 22 A = 1.1 V).

Battery reserve (``battery_reserve``, the node lands; latched): the pack voltage below the one
at which the heaviest-loaded rotor's hover thrust (the model's, given each tick) is more than
``reserve_thrust_fraction`` of its thrust at full duty (``motor_info``'s ``max_thrust`` at its
voltage, times (V / that voltage)^2). ASSUMPTION: 0.93, the rest of the thrust kept for the
attitude loop and the landing while the pack sags on (:class:`MonitorLimits`). A level on the
cell voltage alone (``battery_low``) ignores what the robot needs: 3.5 V/cell is below the
mission robot's hover limit.
"""

from __future__ import annotations

import logging
import math
from collections import Counter, deque
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

LOG = logging.getLogger("rdm.onboard")

#: A fully charged Li-Po cell, V.
CELL_FULL_V = 4.2


@dataclass(frozen=True)
class MonitorLimits:
    """Thresholds of the monitors (every value an ASSUMPTION unless noted)."""

    #: Spinal silent (no ``imu``) for longer than this, s (Spinal publishes ``imu`` at 200 Hz).
    imu_timeout_s: float = 0.1
    #: No ``servo/states`` for longer than this, s (Spinal sends them at about 20 Hz).
    servo_timeout_s: float = 0.5
    #: Battery cells; None: from ``motor_info``'s highest reference voltage.
    battery_cells: int | None = None
    #: Plausible cell voltage range, V (the window of Spinal's voltage guard,
    #: ``rdm_core::pwm``: a Li-Po's discharge cut-off to a high-voltage cell's full charge).
    cell_plausible: tuple[float, float] = (3.0, 4.45)
    #: Land below this cell voltage (sustained ``low_battery_s``), V.
    cell_low: float = 3.5
    low_battery_s: float = 1.0
    #: Refuse to arm below this cell voltage, V.
    cell_arm_min: float = 3.6
    #: Battery sag: the pack voltage (Spinal's low-pass undone, :func:`pack_voltage`) more
    #: than this many V per cell below its highest of the last ``sag_window_s`` trips
    #: ``battery_sag`` (the node lands). ASSUMPTION: 0.2 V/cell (1.2 V for 6S), above a load
    #: step's sag (JSK's hover compensation example: 0.05 ohm x 22 A = 1.1 V from rest to
    #: hover) and 13 times a 6S pack's discharge over the window in a 4 min flight (25.2 to
    #: 21 V: 0.0875 V in 5 s); a 1 V/s sag trips 1.45-1.52 s after it starts (the mission).
    cell_sag_v: float = 0.2
    #: ... the window, s: sags slower than ``cell_sag_v`` x cells per ``sag_window_s`` (0.24
    #: V/s for 6S) are left to ``battery_reserve``. ASSUMPTION: 5 s (a 0.3 V/s sag trips at about
    #: 23.9 V, 8.4 s before the hover's limit; the mission's landing takes 3.5-4 s).
    sag_window_s: float = 5.0
    #: Battery reserve (``battery_reserve``, the node lands): the heaviest-loaded rotor's
    #: hover thrust (the model's static allocation) more than this fraction of the thrust
    #: its motor gives at full duty at the pack voltage (``motor_info``'s ``max_thrust`` x
    #: (V / its reference voltage)^2, the firmware's SQRT-mode voltage factor). ASSUMPTION:
    #: 0.93: 7 % of the thrust left for the attitude loop and the landing's deceleration; for
    #: the mission's robot (14.4 N of 20 N at 25.2 V) the reserve is 22.2 V (3.70 V/cell),
    #: the hover's limit 21.4 V: a sag slower than ``battery_sag``'s 0.24 V/s leaves at
    #: least 3.3 s from the trip to it (the mission's landing: 3.5 s, its duty below the
    #: maximum at 0.15-0.2 V/s). 0.9 lands the robustness campaign's perching runs at its
    #: lowest pack (22.8 V, the perching posture's 14.9 N hover: 90.4 %).
    reserve_thrust_fraction: float = 0.93
    #: What losing the ground station does while perched: "hold" (stay perched) or "land".
    ground_loss_perched: str = "hold"
    #: Joint tracking: a joint whose present angle (``servo/states``) stays further than
    #: ``joint_tracking_rad`` from the goal last sent for ``joint_tracking_s`` trips
    #: ``joint_tracking`` (a stuck or overloaded servo). ASSUMPTION: 0.2 rad for 0.25 s; the
    #: whole mission's largest error is 0.09 rad (the 50 ms servo lead at 0.5 rad/s and the
    #: servos' lag; docs/flying.md).
    joint_tracking_rad: float = 0.2
    joint_tracking_s: float = 0.25
    #: Perching QP: no solution (``infeasible`` or another failed status; the controller then
    #: gives its safe command) in every control tick for ``perch_qp_fail_s`` trips
    #: ``perch_qp_failed``. ASSUMPTION: 2 s (80 ticks at 40 Hz): the contact transient of a
    #: normal perch gives up to 28 infeasible ticks in a row (whole mission, seeds 0-7).
    perch_qp_fail_s: float = 2.0
    #: IMU plausibility (``imu`` from Spinal, :meth:`Monitors.imu_plausible`): a reading
    #: outside these is refused and counted ``imu_implausible``; with no plausible one for
    #: ``imu_timeout_s`` the stale-IMU monitor (``spinal_silent``) trips. Largest
    #: accelerometer component, m/s^2: the ICM-20948's +-8 g full scale (78.45 m/s^2,
    #: jsk-wire-protocols.md sec. 3.2) and 10 % for Spinal's bias and temperature-scale
    #: corrections (ASSUMPTION). No jump limit on the accelerometer: an impact (touchdown,
    #: the perch contact) takes it across its whole range within one sample (the mission's
    #: perch contact: 41 m/s^2 between two samples).
    imu_acc_max: float = 86.3
    #: Largest gyro component, rad/s: the +-2000 deg/s full scale (34.9 rad/s) and 10 %.
    imu_gyro_max: float = 38.4
    #: Largest change of the gyro reading per second between two readings, rad/s^2 (the
    #: time between them: the node's receive times, at least Spinal's 5 ms publishing
    #: interval). ASSUMPTION: 2000 rad/s^2, ten times the mission's largest (about 210
    #: rad/s^2, seeds 0-2, the perch contact included) and below the 5800 rad/s^2 Spinal's
    #: gyro filter can give at all (a full-scale step through its factor-12 IIR at 1 kHz).
    imu_gyro_rate_max: float = 2000.0
    #: Largest rotation of the attitude quaternion per second between two readings, rad/s:
    #: Spinal's estimator turns its attitude with the gyro, so no faster than the gyro's full
    #: scale on every axis (sqrt(3) x 34.9 rad/s); the acceleration correction adds 1/601 of
    #: an angle every third sample. ASSUMPTION: 61 rad/s (the mission's largest: 9 rad/s).
    imu_attitude_rate_max: float = 61.0
    #: Largest | |q| - 1 | of the attitude quaternion. ASSUMPTION: 1e-3; Spinal builds it from
    #: an orthonormal rotation matrix in float32 (the mission's largest: 4e-8).
    imu_quat_norm_tol: float = 1e-3
    #: A lost rotor (``rotor_lost``, :mod:`rdm.nodes.onboard_rotor_loss`): in flight (take-off,
    #: hover, manual, landing; no joint motion; the node's command fresh), roll or pitch off
    #: its target by more than ``rotor_loss_tilt_rad`` while the gyro turns it further faster than
    #: ``rotor_loss_rate_rad_s``. ASSUMPTION: 0.005 rad (the direction of the error) and
    #: 1.5 rad/s; the specific force below is the discriminator. The mission's hover (the
    #: damped roll loop, ``lqi.ROLL_DAMPED_Q``) has a roll std of 0.1-0.2 deg; a dead rotor 0
    #: trips 20-25 ms after the fault, at the first tick whose ``imu`` shows the thrust drop.
    rotor_loss_tilt_rad: float = 0.005
    rotor_loss_rate_rad_s: float = 1.5
    #: ... **and** the accelerometer's specific force (its norm: thrust over mass) below this,
    #: m/s^2: the thrust has dropped. ASSUMPTION: 7.35 (0.75 g); the hover's readings stay at
    #: 9.0 or above, a dead rotor 0 (14.4 of 36.4 N) reads 3.2-5.9 within 25 ms, while a
    #: tilt from a transient (the ESCs holding their pulse through a CAN bus-off) keeps it
    #: near g. Below it a rotor carrying more than a quarter of the weight is lost.
    rotor_loss_specific_force: float = 7.35
    #: ... and above this, m/s^2: not every motor stopped (the Neurons' watchdog after a
    #: 150 ms bus-off: 1.0 m/s^2, a fall, not a lost rotor). ASSUMPTION: 2.5 (a lost rotor 0
    #: reads 3.2 or more).
    rotor_loss_min_specific_force: float = 2.5
    #: With the thrust dropped, the gyro's roll or pitch rate beyond this, rad/s, trips at
    #: once, whatever the attitude error's sign (the first tick that shows a Neuron reset:
    #: roll 0.3 deg the other way, gyro 0.7-1.3 rad/s). ASSUMPTION: 0.5; the 20 fault-free
    #: quick missions never turn faster than 0.75 rad/s away from their target.
    rotor_loss_early_rate_rad_s: float = 0.5
    #: A lighter rotor (rotor 2 or 3, 3.8 N: the specific force barely drops): roll or pitch
    #: past both of the last two targets sent by more than this, rad, turning further faster
    #: than ``rotor_loss_rate_rad_s`` (a body following a jumping target is no lost rotor).
    #: ASSUMPTION: 0.0175 (1 deg); a dead rotor 2 or 3 shows
    #: 1.5-2.7 deg at 1.6-1.9 rad/s 45 ms after the fault, the fault-free missions no tick
    #: turning away from the target faster than 0.75 rad/s.
    rotor_loss_light_tilt_rad: float = 0.0175
    #: ... with the specific force below this, m/s^2 (the thrust dropped a little: under
    #: g, not the impact of a touchdown). ASSUMPTION: 9.5; a dead rotor 2 or 3 reads
    #: 8.95-9.35 at the ticks it trips, a battery-sag landing's touchdown 16.5 (pitch 5 deg
    #: off at 1.7 rad/s: a false trip without this bound).
    rotor_loss_light_specific_force: float = 9.5
    #: The reaction: for ``rotor_loss_arrest_s`` the base thrust of every rotor at
    #: ``rotor_loss_fall_thrust``, N, roll and pitch targets the attitude of the tick (the
    #: turn stopped where it is, not turned back), Table V's LQI gains
    #: (``ControlPipeline.use_arrest_gains``) with the lost rotor's row and its gyro-moment
    #: row zero (Spinal's 1 kHz attitude loop stops the turn with the other rotors, and a
    #: rotor that comes back, a reset Neuron's, gets only the floor), then ARM_OFF (the
    #: motors stop) and the robot falls keeping its attitude. ASSUMPTION: ``motor_info``'s
    #: ``min_thrust`` (1 N) and four control ticks (0.1 s at 40 Hz): with one tick or the
    #: damped roll loop's gains the turn goes on through the fall (docs/flying.md "A lost
    #: rotor").
    rotor_loss_fall_thrust: float = 1.0
    rotor_loss_arrest_s: float = 0.1
    #: A light rotor's arrest, s, with roll and pitch targets 0: the other three rotors can
    #: level the robot (the CoG inside their triangle). ASSUMPTION: 0.3 s (12 ticks); with
    #: the heavy rotor's 0.1 s and the attitude held, a dead rotor 2 or 3 rolls on at about
    #: 1 rad/s through the fall (33-38 deg, 6 seeds each; 0.2 s levelled: 21-23 deg).
    rotor_loss_light_arrest_s: float = 0.3

    def __post_init__(self) -> None:
        for name in (
            "imu_timeout_s",
            "imu_acc_max",
            "imu_gyro_max",
            "imu_gyro_rate_max",
            "imu_attitude_rate_max",
            "imu_quat_norm_tol",
            "servo_timeout_s",
            "low_battery_s",
            "cell_sag_v",
            "sag_window_s",
            "reserve_thrust_fraction",
            "joint_tracking_rad",
            "joint_tracking_s",
            "perch_qp_fail_s",
            "rotor_loss_tilt_rad",
            "rotor_loss_rate_rad_s",
            "rotor_loss_specific_force",
            "rotor_loss_min_specific_force",
            "rotor_loss_early_rate_rad_s",
            "rotor_loss_light_tilt_rad",
            "rotor_loss_light_specific_force",
            "rotor_loss_fall_thrust",
            "rotor_loss_arrest_s",
            "rotor_loss_light_arrest_s",
        ):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"MonitorLimits.{name}={v!r} must be finite and > 0")
        if not (
            self.rotor_loss_min_specific_force
            < self.rotor_loss_specific_force
            <= self.rotor_loss_light_specific_force
        ):
            raise ValueError(
                "MonitorLimits: need rotor_loss_min_specific_force < rotor_loss_specific_force"
                " <= rotor_loss_light_specific_force"
            )
        lo, hi = self.cell_plausible
        if not (0 < lo < self.cell_low < self.cell_arm_min <= hi and math.isfinite(hi)):
            raise ValueError(
                "MonitorLimits: need 0 < cell_plausible[0] < cell_low < cell_arm_min "
                "<= cell_plausible[1]"
            )
        if self.reserve_thrust_fraction > 1.0:
            raise ValueError(
                f"MonitorLimits.reserve_thrust_fraction={self.reserve_thrust_fraction!r} must"
                " be <= 1 (above it the hover needs more thrust than the motors give)"
            )
        if self.battery_cells is not None and not (
            isinstance(self.battery_cells, int) and 1 <= self.battery_cells <= 24
        ):
            raise ValueError(f"MonitorLimits.battery_cells={self.battery_cells!r}: 1..24")
        if self.ground_loss_perched not in ("hold", "land"):
            raise ValueError("MonitorLimits.ground_loss_perched: 'hold' or 'land'")


def battery_cells(voltages: list[float]) -> int:
    """The cell count of a battery whose full voltage is the highest reference voltage."""
    top = max((v for v in voltages if math.isfinite(v) and v > 0), default=CELL_FULL_V)
    return max(1, round(top / CELL_FULL_V))


#: Spinal's battery filter (``bat.h``, jsk-flight-navigation.md sec. 8): every
#: ``SPINAL_BATTERY_SAMPLE_S`` the reading becomes ``SPINAL_BATTERY_FILTER`` x itself plus
#: the rest x the ADC sample.
SPINAL_BATTERY_FILTER = 0.99
SPINAL_BATTERY_SAMPLE_S = 0.02
#: The span the pack voltage is taken over, s: the filter undone over a longer span
#: amplifies the reading's rounding and the count of filter steps between two receive times
#: less (over 0.5 s, 1/(1 - 0.99^25) = 4.5 times; one step miscounted: 3.5 % of the
#: reading's lag). ASSUMPTION: 0.5 s (the pack voltage then lags the pack by about 0.25 s).
PACK_SPAN_S = 0.5
#: Battery readings and pack voltages kept (Spinal publishes every 100 ms: 6 and 21 needed);
#: a faster stream shortens the span and the window rather than growing the lists.
READINGS_KEPT = 64
PACK_KEPT = 256


def pack_voltage(y: float, y0: float, dt: float) -> float:
    """The pack voltage over the ``dt`` s before the Spinal reading ``y``, ``y0`` the reading
    ``dt`` earlier: the filter ``y <- a y + (1 - a) v`` undone over ``dt / 0.02`` steps with
    the pack ``v`` held over them."""
    a = SPINAL_BATTERY_FILTER ** (dt / SPINAL_BATTERY_SAMPLE_S)
    return (y - a * y0) / (1.0 - a)


#: How many of the latest monitor events the status carries.
EVENTS_KEPT = 32
#: Spinal publishes ``imu`` no faster than every 5 ms (``IMU_PUB_INTERVAL``,
#: jsk-wire-protocols.md sec. 1.6): the least time between two readings, s.
IMU_PUB_INTERVAL_S = 0.005


class Monitors:
    """Trip counters, the event list and the battery state (see the module doc)."""

    def __init__(
        self, limits: MonitorLimits, cells: int, max_thrust_at: tuple[float, float] | None = None
    ) -> None:
        self.limits = limits
        self.cells = cells
        #: (reference voltage, the motor's thrust at full duty there), ``motor_info``'s row of
        #: the highest voltage; None: ``battery_reserve`` is not watched
        self.max_thrust_at = max_thrust_at
        self.counts: Counter[str] = Counter()
        #: The latest trips and notes, for the status line (``counts`` counts every one and
        #: each is logged). ASSUMPTION: 32 is enough to see how a flight ended while keeping
        #: a status line short.
        self.events: deque[dict[str, Any]] = deque(maxlen=EVENTS_KEPT)
        #: the time of each monitor's first trip (the event list keeps only the latest)
        self.first_trip: dict[str, float] = {}
        self.voltage: float | None = None
        self._low_since: float | None = None
        #: plausible readings (receive time, V) back to the newest one ``PACK_SPAN_S`` old
        self._readings: deque[tuple[float, float]] = deque(maxlen=READINGS_KEPT)
        #: pack voltages (time, V) of the last ``sag_window_s``
        self._pack: deque[tuple[float, float]] = deque(maxlen=PACK_KEPT)
        self._stale: set[str] = set()
        self._since: dict[str, float] = {}
        #: the last plausible ``imu`` reading: receive time, gyro, quaternion
        self._imu_ok: tuple[float, tuple[float, ...] | None, tuple[float, ...]] | None = None
        #: whether the latest ``imu`` reading was refused (a run of refusals logs once)
        self.imu_refusing = False

    def trip(self, name: str, reason: str, now: float) -> None:
        """Count, log and remember one trip."""
        self.counts[name] += 1
        self.first_trip.setdefault(name, round(now, 4))
        self.events.append({"t": round(now, 4), "monitor": name, "reason": reason})
        LOG.warning("t=%.3f %s: %s", now, name, reason)

    def note(self, name: str, what: str, now: float) -> None:
        """Count, log (info) and remember one event of the flight that is not a fault."""
        self.counts[name] += 1
        self.events.append({"t": round(now, 4), "monitor": name, "reason": what})
        LOG.info("t=%.3f %s: %s", now, name, what)

    # -- battery -------------------------------------------------------------------------
    def battery(self, volts: float, now: float) -> bool:
        """A ``battery_voltage_status`` reading; False if rejected (the last good one kept)."""
        lo, hi = (c * self.cells for c in self.limits.cell_plausible)
        if not (math.isfinite(volts) and lo <= volts <= hi):
            self.trip(
                "battery_implausible",
                f"{volts!r} V outside {lo:.2f}..{hi:.2f} V ({self.cells} cells)",
                now,
            )
            return False
        self.voltage = volts
        if volts >= self.limits.cell_low * self.cells:
            self._low_since = None
        elif self._low_since is None:
            self._low_since = now
        self._track_pack(volts, now)
        return True

    def _track_pack(self, volts: float, now: float) -> None:
        """Add the pack voltage at ``now`` (:func:`pack_voltage` from the newest reading at
        least ``PACK_SPAN_S`` older) and drop those older than ``sag_window_s``."""
        readings = self._readings
        if readings and now < readings[-1][0]:  # the clock went back: start again
            readings.clear()
            self._pack.clear()
        elif readings and now == readings[-1][0]:  # two in one receive: the newer one
            readings.pop()
        while len(readings) >= 2 and now - readings[1][0] >= PACK_SPAN_S - 1e-9:
            readings.popleft()
        if readings and now - readings[0][0] >= PACK_SPAN_S - 1e-9:
            at, y0 = readings[0]
            self._pack.append((now, pack_voltage(volts, y0, now - at)))
        readings.append((now, volts))
        pack = self._pack
        while pack and now - pack[0][0] > self.limits.sag_window_s + 1e-9:
            pack.popleft()

    def battery_sag(self, now: float) -> bool:
        """Whether the pack voltage is more than ``cell_sag_v`` x cells below its highest of
        the last ``sag_window_s`` (trips once per episode)."""
        pack = self._pack
        if not pack:
            return self.stale("battery_sag", False, now, "")
        peak = max(v for _, v in pack)
        latest = pack[-1][1]
        bound = self.limits.cell_sag_v * self.cells
        return self.stale(
            "battery_sag",
            peak - latest > bound,
            now,
            f"pack {latest:.2f} V, {peak - latest:.3f} V below its {peak:.2f} V of the last"
            f" {self.limits.sag_window_s:g} s (more than {bound:.3f} V)",
        )

    def max_thrust(self, volts: float) -> float:
        """The motor's thrust at full duty at the pack voltage ``volts``, N (0 without
        ``max_thrust_at``)."""
        if self.max_thrust_at is None:
            return 0.0
        v_ref, thrust = self.max_thrust_at
        return thrust * (volts / v_ref) ** 2

    def reserve_voltage(self, hover_thrust: float) -> float | None:
        """The pack voltage below which a rotor hovering at ``hover_thrust`` N needs more than
        ``reserve_thrust_fraction`` of its thrust at full duty (None: not watched)."""
        if self.max_thrust_at is None or not (math.isfinite(hover_thrust) and hover_thrust > 0):
            return None
        v_ref, thrust = self.max_thrust_at
        return v_ref * math.sqrt(hover_thrust / (self.limits.reserve_thrust_fraction * thrust))

    def battery_reserve(self, now: float, hover_thrust: float) -> bool:
        """Whether the pack voltage (the latest of :func:`pack_voltage`, Spinal's reading
        before there is one) is below :meth:`reserve_voltage` of the heaviest-loaded rotor's
        hover thrust ``hover_thrust``. Latched: once tripped it holds (a pack does not
        recharge in flight; the hover thrust moving with the posture would trip it again)."""
        floor = self.reserve_voltage(hover_thrust)
        volts = self._pack[-1][1] if self._pack else self.voltage
        if floor is None or volts is None:
            return self.stale("battery_reserve", False, now, "")
        share = hover_thrust / max(self.max_thrust(volts), 1e-9)
        return self.stale(
            "battery_reserve",
            volts < floor or self.active("battery_reserve"),
            now,
            f"pack {volts:.2f} V below {floor:.2f} V: the hover's {hover_thrust:.2f} N is"
            f" {share:.0%} of the thrust at full duty (at most"
            f" {self.limits.reserve_thrust_fraction:.0%})",
        )

    def battery_low(self, now: float) -> bool:
        """Whether the voltage stayed below ``cell_low`` for ``low_battery_s`` (trips once)."""
        low = (
            self._low_since is not None
            and now - self._low_since >= self.limits.low_battery_s - 1e-9
        )
        return self.stale(
            "battery_low",
            low,
            now,
            f"{self.voltage} V below {self.limits.cell_low * self.cells:.2f} V",
        )

    def arm_refusal(self, hover_thrust: float = math.nan) -> str | None:
        """Why arming is refused now (None: allowed): no plausible reading, a reading below
        ``cell_arm_min`` or below :meth:`reserve_voltage` of the heaviest-loaded rotor's hover
        thrust ``hover_thrust`` (NaN: the model not known yet, not checked)."""
        if self.counts["battery_implausible"] and self.voltage is None:
            return "no plausible battery reading"
        if self.voltage is not None and self.voltage < self.limits.cell_arm_min * self.cells:
            return (
                f"battery {self.voltage:.2f} V below {self.limits.cell_arm_min * self.cells:.2f} V"
            )
        floor = self.reserve_voltage(hover_thrust)
        if self.voltage is not None and floor is not None and self.voltage < floor:
            return (
                f"battery {self.voltage:.2f} V below the {floor:.2f} V reserve of the hover's"
                f" {hover_thrust:.2f} N"
            )
        return None

    # -- IMU plausibility ----------------------------------------------------------------
    def imu_plausible(
        self,
        now: float,
        acc: Sequence[float],
        gyro: Sequence[float] | None,
        quat: Sequence[float],
    ) -> bool:
        """Whether an ``imu`` reading (accelerometer, gyro or None when not finite, the
        finite quaternion x, y, z, w) is physically possible: every accelerometer and gyro
        component inside the sensor's range, a unit quaternion, and against the last
        plausible reading no larger gyro change or attitude rotation than the limits allow
        in the time between them (:class:`MonitorLimits`). A refused reading is counted
        ``imu_implausible``; the first of a run of them is logged and kept as an event."""
        lim = self.limits
        reason = None
        if not all(math.isfinite(a) and abs(a) <= lim.imu_acc_max for a in acc):
            reason = f"acc {acc} beyond {lim.imu_acc_max} m/s^2"
        elif gyro is not None and not all(abs(g) <= lim.imu_gyro_max for g in gyro):
            reason = f"gyro {gyro} beyond {lim.imu_gyro_max} rad/s"
        elif abs(math.sqrt(math.fsum([v * v for v in quat])) - 1.0) > lim.imu_quat_norm_tol:
            reason = f"quaternion norm off 1 by more than {lim.imu_quat_norm_tol}"
        elif self._imu_ok is not None:
            at, gyro0, quat0 = self._imu_ok
            dt = max(IMU_PUB_INTERVAL_S, now - at)
            if gyro is not None and gyro0 is not None:
                jump = max(abs(a - b) for a, b in zip(gyro, gyro0, strict=True))
                if jump > lim.imu_gyro_rate_max * dt:
                    reason = f"gyro jumped {jump:.3g} rad/s in {dt:.3f} s"
            if reason is None:
                dot = abs(math.fsum([a * b for a, b in zip(quat, quat0, strict=True)]))
                turn = 2.0 * math.acos(min(1.0, dot / math.sqrt(math.fsum([v * v for v in quat]))))
                if turn > lim.imu_attitude_rate_max * dt:
                    reason = f"attitude turned {turn:.3g} rad in {dt:.3f} s"
        if reason is None:
            kept = self._imu_ok[1] if gyro is None and self._imu_ok is not None else gyro
            self._imu_ok = (now, None if kept is None else tuple(kept), tuple(quat))
            self.imu_refusing = False
            return True
        if self.imu_refusing:
            self.counts["imu_implausible"] += 1
        else:
            self.imu_refusing = True
            self.trip("imu_implausible", reason, now)
        return False

    # -- freshness and limits ------------------------------------------------------------
    def stale(self, name: str, condition: bool, now: float, reason: str) -> bool:
        """True on the tick ``condition`` becomes true (one trip per episode)."""
        if not condition:
            self._stale.discard(name)
            return False
        if name in self._stale:
            return False
        self._stale.add(name)
        self.trip(name, reason, now)
        return True

    def sustained(self, name: str, condition: bool, hold_s: float, now: float, reason: str) -> bool:
        """:meth:`stale` of ``condition`` held without a break for ``hold_s`` s (one trip per
        episode; a tick without it starts the wait again)."""
        if not condition:
            self._since.pop(name, None)
        else:
            self._since.setdefault(name, now)
        held = condition and now - self._since[name] >= hold_s - 1e-9
        return self.stale(name, held, now, reason)

    def active(self, name: str) -> bool:
        """Whether the condition of ``name`` holds at the last check."""
        return name in self._stale

    def status(self) -> dict[str, Any]:
        return {
            "counts": dict(self.counts),
            "active": sorted(self._stale),
            "events": list(self.events),
            "battery_cells": self.cells,
        }
