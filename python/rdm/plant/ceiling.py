"""Ceiling-effect models: thrust gain of a rotor close to an overhead plane.

A rotor near a ceiling produces more thrust at the same speed (Sanchez-Cuevas et al.,
ICUAS 2017; Nishio et al., ICRA 2020). The plant scales each rotor's thrust by
``thrust_ratio(d)``, ``d`` the distance from the rotor centre to the ceiling plane measured
along the rotor axis. Models sit behind :class:`CeilingEffect` so a fitted or aerodynamic
model can replace the default.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable


@runtime_checkable
class CeilingEffect(Protocol):
    """Thrust ratio T/T0 of a rotor at a given distance [m] from the ceiling."""

    def thrust_ratio(self, distance_to_ceiling: float) -> float:
        """T/T0 >= 1 at ``distance_to_ceiling`` (inf: no ceiling in front of the rotor)."""
        ...


@dataclass(frozen=True)
class NoCeilingEffect:
    """The ceiling does not change thrust (T/T0 = 1 everywhere)."""

    def thrust_ratio(self, distance_to_ceiling: float) -> float:
        """Always 1."""
        return 1.0


@dataclass(frozen=True)
class ParametricCeilingEffect:
    """Sanchez-Cuevas form T/T0 = 1 / (1 - (R / (z + k2))^2 / k1), capped at ``max_ratio``.

    ASSUMPTION (no fitted values exist for the 127 mm T-Motor prop): k1 = 4.7 and
    k2 = 0.8 R, chosen so the gain is 1.5 at contact (z = 0), ~1.07 at z = R, < 1.01 beyond
    two diameters. Negative or NaN distances count as contact; the cap keeps the formula away
    from its pole for any coefficients.
    """

    radius: float
    k1: float = 4.7
    k2_over_radius: float = 0.8
    max_ratio: float = 1.5
    # derived once (the plant calls thrust_ratio per rotor at 1 kHz): k2 = k2_over_radius * R
    # and the value of s at which the cap takes over
    _k2: float = field(init=False, repr=False, compare=False)
    _s_cap: float = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if not (self.radius > 0 and self.k1 > 0 and self.k2_over_radius > 0):
            raise ValueError("ParametricCeilingEffect: radius, k1, k2_over_radius must be > 0")
        if not self.max_ratio >= 1.0:
            raise ValueError("ParametricCeilingEffect: max_ratio must be >= 1")
        object.__setattr__(self, "_k2", self.k2_over_radius * self.radius)
        object.__setattr__(self, "_s_cap", 1.0 - 1.0 / self.max_ratio)

    def thrust_ratio(self, distance_to_ceiling: float) -> float:
        """T/T0 at ``distance_to_ceiling`` [m]; 1 for inf, ``max_ratio`` at worst."""
        z = distance_to_ceiling
        if math.isnan(z) or z < 0.0:
            z = 0.0
        if math.isinf(z):
            return 1.0
        s = (self.radius / (z + self._k2)) ** 2 / self.k1
        if s >= self._s_cap:
            return self.max_ratio
        return 1.0 / (1.0 - s)
