"""A lost rotor (a dead ESC, a broken propeller, a Neuron resetting under its ESC): its
detection from Spinal's attitude, gyro and accelerometer, which rotor it is, and the
feasibility figure behind the node's reaction (``OnboardStep._rotor_loss``: for
``rotor_loss_arrest_s`` Spinal's attitude loop, on Table V's gains without the lost rotor's
row, holds the attitude on the thrust floor, then the motors stop).

Why no flight on three rotors (``docs/flying.md`` "A lost rotor"): in the flat posture the
CoG (x 0.483 m) lies 3.9 cm outside the triangle of rotors 1-3 (rotor 0 lost; likewise
rotor 1), and the rotors sit only 2.5 cm above it. Parallel thrusts balance roll and pitch
about the CoG only along the line from the CoG to their centroid, so a hover on them needs
the body tilted about 57 deg (:func:`three_rotor_hover_tilt`); the vectoring units shift a
thrust line by 2.5 cm x tan(tilt) and, with no net sideways force, add no roll or pitch
moment at all. The
reduced-attitude "relaxed hover" on the two diagonal rotors needs the CoG on their diagonal
(3.9 cm off). Losing rotor 2 or 3 (3.8 N in hover, behind the CoG) leaves the CoG inside the
triangle of the other three (yaw then unbalanced); the node treats it as any lost rotor.

Detection (thresholds ``MonitorLimits.rotor_loss_*``), in two classes of rotor:

* a rotor carrying more than a quarter of the weight (rotor 0 or 1 here): the
  accelerometer's specific force below ``rotor_loss_specific_force`` (the thrust dropped)
  and above ``rotor_loss_min_specific_force`` (not every motor stopped), and either roll or
  pitch diverging (:func:`diverging_axis` with ``rotor_loss_tilt_rad``,
  ``rotor_loss_rate_rad_s``) or the gyro turning faster than ``rotor_loss_early_rate_rad_s``
  on roll or pitch (:func:`turning_axis`: the first tick that shows the thrust drop, before
  the attitude error has its sign);
* a lighter rotor (rotor 2 or 3): the specific force barely drops (3.8 of 36.4 N): below
  ``rotor_loss_light_specific_force`` (not a touchdown's impact), with roll or pitch
  diverging beyond ``rotor_loss_light_tilt_rad`` at ``rotor_loss_rate_rad_s`` past both
  of the last two targets sent (``previous`` of :func:`diverging_axis`). Noisy motion
  capture makes the position loop's roll target jump from one 25 ms tick to the next
  (2.6 x the nominal noise: 1.2 deg rms), and Spinal's attitude loop follows each jump:
  the body then turns away from the newest target towards the one before it, 1.3-2.4 deg
  off the newest at 1.6-2.3 rad/s with the specific force at 8.6-9.5 m/s^2, as a dead
  light rotor does (docs/flying.md "A lost rotor"). A dead rotor 2 or 3 turns the body
  past both (1.1-2.8 deg 45-50 ms after the fault; one run 0.4 deg, detected a tick later).

A lost rotor 0 gives the roll axis about 250 rad/s^2 (14.4 N x 0.07 m / 0.004 kg m^2).
:func:`lost_rotor` names the rotor: of the class the specific force gives, the one whose
loss turns the body the way the gyro shows.
"""

from __future__ import annotations

import math

import numpy as np


def diverging_axis(
    tilt_rad: float,
    rate_rad_s: float,
    roll_pitch: tuple[float, float],
    target: tuple[float, float],
    rates: tuple[float, float],
    previous: tuple[float, float] | None = None,
) -> str | None:
    """``"roll"`` or ``"pitch"`` when that axis diverges (see the module doc), else None.
    ``rates``: the gyro's x and y, rad/s. ``previous``: the target sent the tick before
    ``target``; given, the error is the angle's distance beyond both (an angle between
    them, or turning towards the older one, is the attitude loop following its targets)."""
    before = target if previous is None else previous
    for name, angle, goal, old, rate in zip(
        ("roll", "pitch"), roll_pitch, target, before, rates, strict=True
    ):
        error = angle - min(max(angle, min(goal, old)), max(goal, old))
        if abs(error) > tilt_rad and abs(rate) > rate_rad_s and (error > 0) == (rate > 0):
            return name
    return None


def turning_axis(rate_rad_s: float, rates: tuple[float, float]) -> str | None:
    """``"roll"`` or ``"pitch"``: the faster of the two gyro rates (rad/s) when it exceeds
    ``rate_rad_s``, else None."""
    roll, pitch = abs(rates[0]), abs(rates[1])
    if max(roll, pitch) <= rate_rad_s:
        return None
    return "roll" if roll >= pitch else "pitch"


def lost_rotor(
    allocation_bar: np.ndarray,
    hover_thrust: np.ndarray,
    inertia: np.ndarray,
    rates: tuple[float, float],
    heavy: bool,
    weight: float,
) -> int | None:
    """The rotor whose loss explains the turn: among the rotors of the class (``heavy``:
    hover thrust above a quarter of ``weight``, N; else the others), the one whose lost
    hover thrust turns the body most along the gyro's roll and pitch ``rates``. Its
    angular acceleration is ``-f_i (m_x,i / I_xx, m_y,i / I_yy)`` with ``m_x,i``, ``m_y,i``
    the rows of ``allocation_bar`` (f_z, m_x, m_y, m_z; 4 x N, CoG frame) and ``f_i`` its
    hover thrust. None: no rotor of the class, or none turns the body that way."""
    qbar = np.asarray(allocation_bar, dtype=float)
    f = np.asarray(hover_thrust, dtype=float)
    i = np.asarray(inertia, dtype=float)
    accel = -f * np.vstack([qbar[1] / i[0, 0], qbar[2] / i[1, 1]])
    score = np.asarray(rates, dtype=float) @ accel
    member = f > 0.25 * weight if heavy else f <= 0.25 * weight
    score = np.where(member, score, -np.inf)
    best = int(np.argmax(score))
    return best if math.isfinite(score[best]) and score[best] > 0.0 else None


def three_rotor_hover_tilt(
    positions: np.ndarray, cog: np.ndarray, lost: int, gravity_force: float
) -> tuple[np.ndarray | None, float]:
    """The thrusts of the three remaining rotors (vertical in the body, rows of
    ``positions`` in the frame of ``cog``) that balance roll and pitch at ``gravity_force``
    along the body's z, and the body tilt, rad, a hover on them needs: the angle between the
    body's z and the line from the CoG to the thrust centroid (parallel thrusts only balance
    about the CoG when that line is their direction). None: no nonnegative thrusts balance
    the moments level. Used by the feasibility figure of ``docs/flying.md``."""
    keep = [i for i in range(len(positions)) if i != lost]
    r = np.asarray(positions, dtype=float)[keep] - np.asarray(cog, dtype=float)
    a = np.vstack([np.ones(len(keep)), r[:, 1], -r[:, 0]])
    level = None
    if len(keep) == 3:
        f = np.linalg.solve(a, np.array([gravity_force, 0.0, 0.0]))
        level = f if bool(np.all(f >= 0.0)) else None
    # the nearest point of the remaining rotors' convex hull (in x, y) to the CoG: the
    # smallest horizontal offset of any nonnegative thrust centroid
    best = math.inf
    n = len(keep)
    for i in range(n):
        for j in range(n):
            p, q = r[i, :2], r[j, :2]
            d = q - p
            t = 0.0 if not d.any() else float(np.clip(-(p @ d) / (d @ d), 0.0, 1.0))
            best = min(best, float(np.linalg.norm(p + t * d)))
    if level is not None:
        best = 0.0
    height = float(np.mean(r[:, 2]))
    return level, math.atan2(best, abs(height))
