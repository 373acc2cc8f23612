"""Horizontal position control and vectoring angles (paper Sec. IV-A-2, eqs. 30-36).

Defaults are the paper's Table V; the integral clamp (1 m/s^2 per axis) is an assumption, and
so is the tilt bound ``max_tilt`` (:data:`MAX_TILT_RAD`, the attitude controller's 1.0 rad):
roll/pitch targets, the vectoring directions' lean and the desired acceleration
(``g tan(max_tilt)``) are cut to it, and the step says so (``saturated``, ``saturation``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rdm import _rdm

PositionControlError = _rdm.PositionControlError
N_VECTORING: int = _rdm.N_VECTORING
GRAVITY: float = _rdm.GRAVITY
MAX_TILT_RAD: float = _rdm.MAX_TILT_RAD
vectoring_angles = _rdm.vectoring_angles


@dataclass(frozen=True)
class PositionCommand:
    """Outputs of one step: desired acceleration, roll/pitch targets, apparatus angles."""

    acceleration: np.ndarray
    roll: float
    pitch: float
    alpha: tuple[float, ...]
    beta: tuple[float, ...]
    direction: np.ndarray
    integral_clamped: bool
    #: True when an output was cut to the tilt bound this step.
    saturated: bool = False
    #: The cut outputs' names ("acceleration", "attitude", "vectoring").
    saturation: tuple[str, ...] = ()


class PositionController:
    """PID on world x/y to acceleration, then eqs. (31)-(36)."""

    def __init__(self, **gains: object) -> None:
        """Keyword gains: x_pid, y_pid (P, I, D), integral_limit (x, y) [m/s^2], k_roll,
        k_pitch, k_pitch_vectoring, k_roll_vectoring (per apparatus), gravity, max_tilt [rad]
        in (0, pi/2)."""
        self._core = _rdm.PositionController(**gains)

    def step(
        self,
        position: np.ndarray,
        velocity: np.ndarray,
        target_position: np.ndarray,
        target_velocity: np.ndarray,
        target_yaw: float,
        link_rotations: np.ndarray,
        dt: float,
    ) -> PositionCommand:
        """One step; ``link_rotations`` (N_VECTORING, 3, 3) is the rotation eq. (36) applies."""
        out = self.step_outputs(
            position, velocity, target_position, target_velocity, target_yaw, link_rotations, dt
        )
        return PositionCommand(
            acceleration=out["acceleration"],
            roll=out["roll"],
            pitch=out["pitch"],
            alpha=tuple(out["alpha"]),
            beta=tuple(out["beta"]),
            direction=np.asarray(out["direction"]),
            integral_clamped=out["integral_clamped"],
            saturated=out["saturated"],
            saturation=tuple(out["saturation"]),
        )

    def step_outputs(
        self,
        position: np.ndarray,
        velocity: np.ndarray,
        target_position: np.ndarray,
        target_velocity: np.ndarray,
        target_yaw: float,
        link_rotations: np.ndarray,
        dt: float,
    ) -> dict:
        """:meth:`step` as the core returns it: a dict with ``acceleration`` (array), ``roll``,
        ``pitch`` (floats), ``alpha``, ``beta`` (lists of floats), ``direction`` (list of
        [x, y, z] lists), ``integral_clamped``, ``saturated``, ``saturation`` (list of names);
        no :class:`PositionCommand` is built."""
        vec = np.ascontiguousarray
        return self._core.step(
            vec(position, dtype=float),
            vec(velocity, dtype=float),
            vec(target_position, dtype=float),
            vec(target_velocity, dtype=float),
            float(target_yaw),
            vec(link_rotations, dtype=float),
            float(dt),
        )

    @property
    def integral(self) -> np.ndarray:
        """Integral of the x/y position error [m s]."""
        return self._core.integral

    def reset(self) -> None:
        """Zero the integrators."""
        self._core.reset()

    def take_integral_action(self, previous: PositionController) -> None:
        """Bumpless gain switch: carry ``previous``'s integral action ``k_I ∫e`` per axis
        (``∫e`` rescaled by ``k_I,old / k_I,new``, clamped to this controller's
        ``integral_limit``; 0 on an axis whose new ``k_I`` is 0)."""
        self._core.take_integral_action(previous._core)
