"""A lost rotor (a dead ESC, a broken propeller): its detection from Spinal's attitude and
gyro, and the feasibility figure behind the node's reaction (a cut: the motors stop after
``rotor_loss_arrest_s`` of Spinal's attitude loop on the thrust floor with Table V's gains,
``OnboardStep._rotor_loss``).

Why no flight on three rotors (``docs/flying.md`` "A lost rotor"): in the flat posture the
CoG (x 0.483 m) lies 3.9 cm outside the triangle of rotors 1-3 (rotor 0 lost; likewise
rotor 1), and the rotors sit only 2.5 cm above it. Parallel thrusts balance roll and pitch
about the CoG only along the line from the CoG to their centroid, so a hover on them needs
the body tilted about 57 deg (:func:`three_rotor_hover_tilt`); the vectoring units shift a
thrust line by 2.5 cm x tan(tilt) and, with no net sideways force, add no roll or pitch
moment at all. The
reduced-attitude "relaxed hover" on the two diagonal rotors needs the CoG on their diagonal
(3.9 cm off). Losing rotor 2 or 3 (3.8 N in hover, behind the CoG) leaves the CoG inside the
triangle of the other three (yaw then unbalanced); that case is not handled separately (and
its thrust drop is too small for the detection).

Detection (:func:`diverging_axis`, thresholds ``MonitorLimits.rotor_loss_*``): on roll or
pitch, the attitude error against the target last sent beyond ``rotor_loss_tilt_rad`` **and**
the gyro turning it further (same sign) faster than ``rotor_loss_rate_rad_s``; the node adds
the thrust drop (the accelerometer's specific force below ``rotor_loss_specific_force``). A
lost rotor gives the roll axis about 250 rad/s^2 (14.4 N x 0.07 m / 0.004 kg m^2).
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
) -> str | None:
    """``"roll"`` or ``"pitch"`` when that axis diverges (see the module doc), else None.
    ``rates``: the gyro's x and y, rad/s."""
    for name, angle, goal, rate in zip(("roll", "pitch"), roll_pitch, target, rates, strict=True):
        error = angle - goal
        if abs(error) > tilt_rad and abs(rate) > rate_rad_s and (error > 0) == (rate > 0):
            return name
    return None


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
