"""Ceiling-effect model: formula, bounds, monotonicity, and its use inside the plant."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from rdm.plant import CeilingEffect, NoCeilingEffect, ParametricCeilingEffect, Plant

R = 0.127 / 2


def reference_ratio(z: float, k1: float = 4.7, k2: float = 0.8 * R) -> float:
    """Sanchez-Cuevas form, written out again: 1 / (1 - (R / (z + k2))^2 / k1)."""
    return 1.0 / (1.0 - (R / (z + k2)) ** 2 / k1)


@pytest.mark.parametrize("z", [0.0, 0.005, 0.02, 0.05, R, 0.127, 0.3, 1.0])
def test_formula(z: float) -> None:
    assert ParametricCeilingEffect(radius=R).thrust_ratio(z) == pytest.approx(reference_ratio(z))


def test_bounds_and_far_field() -> None:
    model = ParametricCeilingEffect(radius=R)
    assert 1.4 < model.thrust_ratio(0.0) <= 1.5
    assert model.thrust_ratio(2 * 0.127) < 1.01  # two diameters away
    assert model.thrust_ratio(math.inf) == 1.0
    assert model.thrust_ratio(-0.01) == model.thrust_ratio(0.0)
    assert model.thrust_ratio(math.nan) == model.thrust_ratio(0.0)
    assert isinstance(model, CeilingEffect) and isinstance(NoCeilingEffect(), CeilingEffect)


def test_cap_is_continuous_for_aggressive_coefficients() -> None:
    """k1 = 1, k2 = 0.5 R has a pole at z = 0.5 R; the cap keeps it finite and continuous."""
    model = ParametricCeilingEffect(radius=R, k1=1.0, k2_over_radius=0.5, max_ratio=2.0)
    z = np.linspace(0.0, 0.3, 3001)
    r = np.array([model.thrust_ratio(float(v)) for v in z])
    assert r.max() == 2.0 and np.all(np.isfinite(r))
    assert np.max(np.abs(np.diff(r))) < 0.01  # no jump at the clamp


@given(st.floats(0.0, 2.0), st.floats(1e-6, 0.5))
def test_monotone_decreasing_with_distance(z: float, dz: float) -> None:
    model = ParametricCeilingEffect(radius=R)
    assert model.thrust_ratio(z + dz) <= model.thrust_ratio(z)
    assert model.thrust_ratio(z) >= 1.0


def test_invalid_coefficients_rejected() -> None:
    with pytest.raises(ValueError, match="radius"):
        ParametricCeilingEffect(radius=0.0)


def test_plant_scales_each_rotor_by_its_distance_to_the_ceiling() -> None:
    """Straight arm, rotors 5 cm below the ceiling along +z: force = T * ratio(0.05)."""
    plant = Plant("rdm", ceiling_height=2.0)
    # Rotor planes sit 0.02 m below the foot contact face (URDF: q1 axis 0.05 below the
    # face, rotors 0.03 above their unit axis), so the foot frame goes 3 cm below the ceiling.
    plant.reset(base_position=(0.0, 0.0, 2.0 - 0.03), thrusts=[5.0] * 4)
    plant.set_rotor_thrusts([5.0] * 4)
    plant.step(1)
    assert np.allclose(plant.rotor_distances_to_ceiling(), 0.05, atol=1e-4)
    assert np.allclose(plant.rotor_thrusts(), 5.0 * reference_ratio(0.05), rtol=1e-3)
    # Tilted rotors measure along the axis: beta1 = 0.5 rad tilts rotors 1, 2.
    q = np.zeros(10)
    q[7] = 0.5
    plant.reset(q0=q, base_position=(0.0, 0.0, 1.0))
    d = plant.rotor_distances_to_ceiling()
    z_site = plant.data.site_xpos[plant._rotor_site[0]][2]
    assert d[0] == pytest.approx((2.0 - z_site) / math.cos(0.5))
