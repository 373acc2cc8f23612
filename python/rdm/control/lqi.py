"""LQI attitude/altitude gain synthesis (paper Sec. IV-A-1, eqs. 21-29) over the Rust core.

State order (JSK ``lqi_mode`` 4)::

    x = [z, z_dot, roll, roll_dot, pitch, pitch_dot, yaw, yaw_dot, int_z, int_roll,
         int_pitch, int_yaw]

Gain arrays have shape ``(rotors, 4, 3)``: axes ``(roll, pitch, yaw, z)``, terms
``(P, I, D)``. Weights default to the paper's Table V (see docs/lqi.md).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rdm import _rdm

#: Paper index (x = [xi_bar; xi_bar_dot; v], eq. 26) of each JSK-order state.
JSK_TO_PAPER: tuple[int, ...] = tuple(_rdm.JSK_TO_PAPER)
#: Largest |gain| that fits the int16 x 0.001 ``rpy/gain`` wire format.
MAX_WIRE_GAIN: float = _rdm.MAX_WIRE_GAIN
#: Table V, W1 in JSK state order.
TABLE_V_Q = np.array([20.0, 30.0, 90.0, 12.8, 600.0, 80.0, 100.0, 50.0, 20.0, 0.15, 1.0, 0.5])
#: Table V, W2.
TABLE_V_R = np.ones(4)
#: Table V's W1 with the roll weights lowered (roll 90 -> 30, roll rate 12.8 -> 1.0) for the
#: straight posture, whose roll inertia is small (I_xx 0.0042 kg m^2, 70x below I_yy). With
#: Table V's weights the roll-rate loop's gain (K_d / I_xx = 123 1/s) sits above what the
#: rotor lag, Spinal's gyro filter and the transport delay leave: a 12 Hz roll mode with
#: damping about 0.03 in MuJoCo, rung to +-1 deg by motion capture's noise through the
#: position loop's roll target and vectoring angle (docs/flying.md "The hover's roll loop").
#: ASSUMPTION (tuned in simulation: the mission's hover thrust std per rotor 1.3-2.0 N ->
#: 0.18-0.30 N over 20 seeds); JSK tunes its LQI weights per robot (``controller/lqi`` yaml).
ROLL_DAMPED_Q = np.array([20.0, 30.0, 30.0, 1.0, 600.0, 80.0, 100.0, 50.0, 20.0, 0.15, 1.0, 0.5])

CareSolveError = _rdm.CareSolveError
LqiSynthesisError = _rdm.LqiSynthesisError
solve_care = _rdm.solve_care
augmented_system = _rdm.augmented_system
gain_set_from_k = _rdm.gain_set_from_k
gyro_compensation = _rdm.gyro_compensation
flight_thrust = _rdm.flight_thrust
PcAxisController = _rdm.PcAxisController


@dataclass(frozen=True)
class LqiResult:
    """One synthesis: K (lambda_bar = K x_bar), P, B_bar, the Spinal gain set and solver info."""

    k: np.ndarray
    p: np.ndarray
    b: np.ndarray
    gains: np.ndarray
    clamp_scales: tuple[float, float, float, float, float]
    method: str
    iterations: int
    fell_back: bool
    relative_residual: float


def _result(out: dict) -> LqiResult:
    """``LqiResult`` of the core's dict, without the frozen-dataclass ``__init__`` (one per
    control tick)."""
    report = out["report"]
    result = object.__new__(LqiResult)
    result.__dict__.update(
        k=out["k"],
        p=out["p"],
        b=out["b"],
        gains=out["gains"],
        clamp_scales=out["clamp_scales"],
        method=report["method"],
        iterations=report["iterations"],
        fell_back=report["fell_back"],
        relative_residual=report["relative_residual"],
    )
    return result


class LqiSynthesizer:
    """Warm-started LQI synthesizer; ``synthesize`` releases the GIL while solving."""

    def __init__(
        self,
        q_weights: np.ndarray | None = None,
        r_weights: np.ndarray | None = None,
        clamp_gain: bool = True,
        kleinman_tolerance: float | None = None,
        rotors: int | None = None,
    ) -> None:
        """``rotors``: the rotor count (1..8), fixed for this synthesizer; None: the length
        of ``r_weights``, or 4 (the paper's RDM) without them."""
        q = None if q_weights is None else np.ascontiguousarray(q_weights, dtype=float)
        r = None if r_weights is None else np.ascontiguousarray(r_weights, dtype=float)
        self._core = _rdm.LqiSynthesizer(q, r, clamp_gain, kleinman_tolerance, rotors)

    @property
    def rotors(self) -> int:
        """The rotor count fixed at construction."""
        return int(self._core.rotors)

    def synthesize(self, mass: float, inertia: np.ndarray, allocation: np.ndarray) -> LqiResult:
        """Gains for mass [kg], inertia (3x3, CoG frame) and allocation Q_bar (4 x rotors)."""
        out = self._core.synthesize(
            float(mass),
            np.ascontiguousarray(inertia, dtype=float),
            np.ascontiguousarray(allocation, dtype=float),
        )
        return _result(out)

    def synthesize_wire(
        self, mass: float, inertia: np.ndarray, allocation: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray | None, bytes | None, bool, bool, bool]:
        """:meth:`synthesize` (the same solve and gains) in the form the onboard tick uses:
        ``(gains, wire, payload, finite, fell_back, clamped)``. ``wire`` is
        ``gains_to_wire_terms(gains)`` (int16, rotors x 7) and ``payload`` its
        ``spinal/RollPitchYawTerms`` bytes, both None where that raises (NaN/inf term);
        ``finite``: every gain finite; ``clamped``: a clamp scale is not 1. A result with
        ``wire`` and ``finite`` is kept for :meth:`kept_result`. The last result again
        (its problem asked again) returns the same objects again (read-only arrays)."""
        return self._core.synthesize_wire(
            float(mass),
            np.ascontiguousarray(inertia, dtype=float),
            np.ascontiguousarray(allocation, dtype=float),
        )

    def kept_result(self) -> LqiResult | None:
        """The :class:`LqiResult` of the last result :meth:`synthesize_wire` kept."""
        out = self._core.kept_result()
        return None if out is None else _result(out)

    def reset(self) -> None:
        """Forget the warm start and the kept solutions (next synthesis is cold)."""
        self._core.reset()

    @property
    def has_solution(self) -> bool:
        """Whether the next synthesis is warm-started."""
        return self._core.has_solution

    @property
    def reused(self) -> int:
        """Calls answered with a kept solution because their B-bar (eq. 25) was bitwise
        one of the last four solved: the gains are a function of the problem, not of how
        often it is solved (``synthesize_wire`` returns the same read-only objects while
        the same problem is asked again)."""
        return self._core.reused
