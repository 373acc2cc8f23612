"""The foot plate's contact measurement in Rust (``rdm._rdm.PlateContactCore``, used by
``FootContactTracker.measure_contacts``, its only form): the bits of a numpy derivation
through ``mj_contactForce`` for elliptic and pyramidal cones, the force MuJoCo itself puts
on the plate, NaN sums and bad inputs."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
from test_plant_physics import _perch_plant, _perch_thrusts
from test_truthlog_truth import _measures_equal
from truth_reference import measure_reference

from rdm._rdm import PlateContactCore
from rdm.plant import NoCeilingEffect


def _perched_run(steps: int, every: int):
    """Twin-free perched run: pressed on the ceiling, pushed and twisted, released; yields
    the plant every ``every`` steps."""
    thrust = _perch_thrusts(4.0)
    plant = _perch_plant(NoCeilingEffect())
    plant.reset(base_position=(0.0, 0.0, 2.0 - 5e-4), thrusts=thrust)
    plant.set_rotor_thrusts(thrust)
    for k in range(steps):
        if k == 200:
            plant.apply_body_wrench("foot_plate", force=(0.0, 6.0, 0.0), torque=(0.0, 0.0, 1.5))
        if k == 500:
            plant.apply_body_wrench("foot_plate", force=(0.0, 0.0, 0.0))
        if k == 700:
            plant.set_rotor_thrusts(np.zeros(4))
        plant.step(1)
        if k % every == 0:
            yield plant


def test_the_rust_measurement_has_the_bits_of_mujocos_contact_forces_summed():
    seen = set()
    for plant in _perched_run(900, 3):
        tracker, d = plant._tracker, plant._fresh()
        # same data, same anchor: each one's bookkeeping (_track) leaves the same state
        rust = tracker.measure_contacts(d)
        _measures_equal(rust, measure_reference(tracker, d))
        seen.add((rust[0], rust[5] != 0.0))
    assert {n for n, _ in seen} == {0, 1, 2, 3, 4}
    assert any(n > 0 and yaw for n, yaw in seen)


def test_the_measured_force_is_the_force_mujoco_puts_on_the_plate():
    """Independent of the contact list: MuJoCo's ``cfrc_ext`` of the plate body (force part,
    world axes) less the applied push (``xfrc_applied``) is the environment's force on it;
    the measurement reports the robot's force on the environment in the plate frame."""
    checked = 0
    for plant in _perched_run(500, 25):
        m, d = plant.model, plant._fresh()
        tracker = plant._tracker
        points, force, _torque, _zmp, _slip, _yaw = tracker.measure_contacts(d)
        if points == 0:
            continue
        mujoco.mj_rnePostConstraint(m, d)
        pb = tracker._plate_body
        on_plate = d.cfrc_ext[pb][3:] - d.xfrc_applied[pb][:3]
        rot = d.xmat[pb].reshape(3, 3)
        np.testing.assert_allclose(rot @ -force, on_plate, rtol=1e-9, atol=1e-9)
        checked += 1
    assert checked >= 15


def test_a_pyramidal_cone_is_decoded_as_mj_contact_force_does():
    # Perched, pushed and twisted under a pyramidal cone (friction rows decoded with each
    # contact's mu), against the mj_contactForce derivation on a twin plant.
    thrust = _perch_thrusts(4.0)
    plants = []
    for _ in range(2):
        p = _perch_plant(NoCeilingEffect())
        p.model.opt.cone = mujoco.mjtCone.mjCONE_PYRAMIDAL
        p.reset(base_position=(0.0, 0.0, 2.0 - 5e-4), thrusts=thrust)
        p.set_rotor_thrusts(thrust)
        plants.append(p)
    fast, plain = plants
    tangential = 0
    for k in range(400):
        for p in plants:
            if k == 100:
                p.apply_body_wrench("foot_plate", force=(0.0, 6.0, 0.0), torque=(0.0, 0.0, 1.5))
            p.step(1)
        if k % 5 == 0:
            a = fast._tracker.measure_contacts(fast._fresh())
            b = measure_reference(plain._tracker, plain._fresh())
            _measures_equal(a, b)
            tangential += a[0] > 0 and abs(a[1][1]) > 1e-3
    assert tangential > 10  # the decoded friction forces were exercised


def test_nan_sums_stay_nan_where_the_derivation_has_nan():
    thrust = _perch_thrusts(4.0)
    plants = [_perch_plant(NoCeilingEffect()) for _ in range(2)]
    for p in plants:
        p.reset(base_position=(0.0, 0.0, 2.0 - 5e-4), thrusts=thrust)
        p.set_rotor_thrusts(thrust)
        p.step(60)
    fast, ref = plants
    for p in plants:
        assert p._fresh().ncon > 0
        p._data.contact.pos[0] = [np.nan, 0.0, np.inf]
    with np.errstate(invalid="ignore"):
        a = fast._tracker.measure_contacts(fast._data)
        b = measure_reference(ref._tracker, ref._data)
    assert a[0] == b[0] > 0
    for x, y in zip(a[1:5], b[1:5], strict=True):
        x, y = np.asarray(x), np.asarray(y)
        assert np.array_equal(np.isnan(x), np.isnan(y))
        assert x[~np.isnan(x)].tobytes() == y[~np.isnan(y)].tobytes()
    assert np.isnan(a[2]).any()  # the torque (a NaN contact position)


def _views(n: int = 1):
    geom = np.zeros((n, 2), dtype=np.int32)
    geom[:, 1] = 1
    frame = np.tile(np.eye(3).ravel(), (n, 1))
    pos = np.zeros((n, 3))
    dim = np.full(n, 3, dtype=np.int32)
    return geom, frame, pos, np.zeros(n, dtype=np.int32), dim, np.ones((n, 5))


def test_bad_inputs_raise_instead_of_reading_out_of_range():
    core = PlateContactCore([0, 1, 2], [True, False, False], 1)
    geom, frame, pos, adr, dim, mu = _views()
    origin, rot = np.zeros(3), np.eye(3).ravel()
    force = np.array([2.0, 0.1, 0.0])
    points, f, t, zmp = core.measure(geom, frame, pos, adr, dim, mu, force, origin, rot, False)
    assert points == 1 and f.tolist() == [-2.0, -0.1, -0.0] and zmp.tolist() == [0.0, 0.0]
    assert t.tolist() == [0.0, 0.0, 0.0]  # at the origin, no torsion (dim 3)
    with pytest.raises(ValueError, match="flags"):
        PlateContactCore([0, 1], [True], 1)
    with pytest.raises(ValueError, match="contact views"):
        core.measure(geom, frame[:, :8], pos, adr, dim, mu, force, origin, rot, False)
    with pytest.raises(ValueError, match="contact views"):
        core.measure(geom, frame, pos, adr[:0], dim, mu, force, origin, rot, False)
    with pytest.raises(IndexError, match="efc_force"):
        core.measure(geom, frame, pos, adr, dim, mu, force[:2], origin, rot, False)
    with pytest.raises(IndexError, match="efc_force"):
        core.measure(geom, frame, pos, adr, np.full(1, 7, np.int32), mu, force, origin, rot, False)
    with pytest.raises(IndexError, match="geom 9"):
        far = np.array([[9, 1]], np.int32)
        core.measure(far, frame, pos, adr, dim, mu, force, origin, rot, False)
    with pytest.raises(ValueError, match="origin"):
        core.measure(geom, frame, pos, adr, dim, mu, force, origin[:2], rot, False)
    with pytest.raises(ValueError, match="r1"):
        PlateContactCore.yaw_about(rot, rot[:8])
    with pytest.raises(ValueError, match="contact views"):
        core.measure(geom, frame, pos, adr, dim, mu[:, :4], force, origin, rot, False)
    # a pyramidal contact reads 2 (dim - 1) = 4 rows: three are too few
    with pytest.raises(IndexError, match="efc_force"):
        core.measure(geom, frame, pos, adr, dim, mu, force, origin, rot, True)
    # NaN sums stay NaN
    nan = core.measure(geom, frame, pos, adr, dim, mu, force * np.nan, origin, rot, False)
    assert np.isnan(nan[1]).all() and np.isnan(nan[3]).all()
    bad = rot.copy()
    bad[0] = np.nan
    assert PlateContactCore.yaw_about(rot, bad) is None
