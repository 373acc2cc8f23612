"""The ground-truth record in one Rust call (``RotorPlantCore.truth_record``, with its own
no-contact numbers for the flying robot or the tracker's measurement) against the truth
derived directly from MuJoCo (``truth_reference.ground_truth_reference``: the contact
objects, ``mj_contactForce``, numpy copies); the contact measurement in Rust against that
derivation."""

from __future__ import annotations

import math
import struct
from collections.abc import Iterator
from contextlib import contextmanager

import numpy as np
import pytest
from test_plant_physics import _perch_plant, _perch_thrusts
from truth_reference import ground_truth_reference, measure_reference

from rdm._rdm import RotorPlantCore
from rdm.plant import NoCeilingEffect, Plant
from rdm.plant.truth import TRUTH_FIELDS, GroundTruth, _cross3


def _assert_same(a: GroundTruth, b: GroundTruth) -> None:
    assert type(a) is type(b) is GroundTruth
    assert list(a.__dict__) == list(b.__dict__) == list(TRUTH_FIELDS)
    for k in TRUTH_FIELDS:
        x, y = a.__dict__[k], b.__dict__[k]
        assert type(x) is type(y), k
        if isinstance(x, np.ndarray):
            assert x.dtype == y.dtype and x.shape == y.shape, k
            assert x.tobytes() == y.tobytes(), k  # bit for bit (signed zeros, NaN bits)
            assert x.flags.writeable and x.flags.c_contiguous, k
        elif isinstance(x, float):
            assert struct.pack("<d", x) == struct.pack("<d", y), k
        else:
            assert x == y, k


@contextmanager
def _free_records(plant: Plant) -> Iterator[list[bool]]:
    """Per ``truth_record`` call of ``plant``'s rotor core while the block runs, whether it
    wrote the no-contact numbers itself (no measurement given; a spy in front of it)."""
    calls: list[bool] = []
    real = plant._rotors

    class Spy:
        def __getattr__(self, name):
            if name != "truth_record":
                return getattr(real, name)

            def record(*args):
                calls.append(len(args) == 8 and args[7] is None)
                return real.truth_record(*args)

            return record

    plant._rotors = Spy()
    try:
        yield calls
    finally:
        plant._rotors = real


def _takeoff_plants(fixed_base: bool = False, n: int = 3) -> list[Plant]:
    plants = []
    for _ in range(n):
        p = Plant("rdm", seed=2, ceiling_height=1.6, floor_height=0.0, fixed_base=fixed_base)
        p.reset(base_position=(0.0, 0.0, 0.05))
        plants.append(p)
    return plants


@pytest.mark.parametrize("fixed_base", [False, True])
def test_one_call_record_equals_the_reference_through_takeoff_and_flight(fixed_base):
    # On the floor (contacts, an anchor), lift-off (anchor released after 0.1 s), flight
    # with changing thrusts and joint targets: the core writes the no-contact numbers
    # itself whenever the tracker is idle without plate contact, and every record equals
    # the reference derivation on a twin plant.
    fast, plain = _takeoff_plants(fixed_base, n=2)
    rng = np.random.default_rng(5)
    free_calls: list[bool] = []
    idle_seen = {True: 0, False: 0}
    for k in range(1200):
        if k == 200 or (k > 200 and k % 150 == 0):
            thrusts = rng.uniform(8.0, 11.0, 4)
            targets = rng.uniform(-0.4, 0.4, len(fast._qadr))
            for p in (fast, plain):
                p.set_rotor_thrusts(thrusts)
                p.set_servo_targets(targets)
        for p in (fast, plain):
            p.step(1)
        if k % 4 == 0:
            idle = fast._fresh().ncon == 0 and fast._tracker.idle()
            idle_seen[idle] += 1
            with _free_records(fast) as calls:
                a = fast._ground_truth()
            assert len(calls) == 1
            free_calls += calls
            if idle:
                assert calls == [True]
            if calls == [True]:  # the core's numbers only where they are the measurement's
                assert a.foot_contact_points == 0 and not a.foot_slip.any()
            _assert_same(a, ground_truth_reference(plain))
            # the tracker state stays in step too (the one-call path changes nothing)
            assert plain._tracker.last_contact_time == fast._tracker.last_contact_time
            assert (plain._tracker.anchor_pos is None) is (fast._tracker.anchor_pos is None)
    if not fixed_base:
        assert idle_seen[True] > 50 and idle_seen[False] > 10  # both kinds were exercised
        # on the floor resting on other links counts as free too; in contact, a measurement
        assert idle_seen[True] <= sum(free_calls) < len(free_calls)


def test_records_are_fresh_arrays_not_views_or_shared():
    (plant,) = _takeoff_plants(n=1)
    plant.reset(base_position=(0.0, 0.0, 0.8))
    plant.set_rotor_thrusts([9.0, 9.0, 9.0, 9.0])
    plant.step(5)
    a = plant._ground_truth()
    assert plant._tracker.idle() and a.foot_contact_points == 0
    b = plant._ground_truth()
    for k in TRUTH_FIELDS:
        x, y = a.__dict__[k], b.__dict__[k]
        if isinstance(x, np.ndarray):
            assert x is not y and not np.shares_memory(x, y), k
            assert x.base is None, k  # owns its data: not a view of MjData
    before = a.base_position.copy()
    plant.step(20)
    plant.sync()
    assert a.base_position.tobytes() == before.tobytes()
    with pytest.raises(AttributeError):
        a.time = 1.0  # still a frozen record


def test_non_finite_plate_frame_gives_the_reference_bits():
    # The core's no-contact force and torque are -(R.T @ 0) summed in row order: NaN in the
    # column of a non-finite entry, the NaN bits numpy's form gives.
    plant, ref = _takeoff_plants(n=2)
    for p in (plant, ref):
        p.reset(base_position=(0.0, 0.0, 0.8))
        p.sync()
    for value in (np.nan, np.inf, -np.inf):
        for p in (plant, ref):
            p._data.xmat[p._plate_body][4] = value
        with _free_records(plant) as calls, np.errstate(invalid="ignore"):
            a = plant._ground_truth()
            _assert_same(a, ground_truth_reference(ref))
        assert calls == [True]
        # -(R.T @ 0): NaN in the column of the non-finite entry (R[1, 1])
        assert np.isnan(a.foot_contact_force[1]) and not np.isnan(a.foot_contact_force[0])


def test_negated_product_with_zeros_is_negative_zero_for_finite_frames():
    # The no-contact force and torque are -(R.T @ zeros(3)): numpy's matmul gives +0.0 for
    # every finite R (the sums start from +0.0), so -0.0; the Rust record writes -0.0.
    rng = np.random.default_rng(1)
    zeros = np.zeros(3)
    for i in range(20_000):
        r = rng.normal(size=9) * 10.0 ** rng.integers(-300, 300, size=9)
        if i % 3 == 0:
            r = -np.abs(r)
        if i % 7 == 0:
            r[rng.integers(0, 9, size=4)] = -0.0
        if i % 11 == 0:
            r[:] = -0.0
        rot = r.reshape(3, 3)
        assert (-(rot.T @ zeros)).tobytes() == np.full(3, -0.0).tobytes()


def test_record_setup_and_call_errors():
    plant = Plant("rdm", seed=0)
    plant.sync()
    d = plant._data
    views = (d.xpos, d.xquat, d.xmat, d.qpos, d.qvel, d.subtree_com)
    fresh = RotorPlantCore([], [], None, d.site_xpos, d.site_xmat, d.ctrl)
    with pytest.raises(ValueError, match="set_truth_record"):
        fresh.truth_record(0.0, *views)
    with pytest.raises(ValueError, match="fields"):
        fresh.set_truth_record(object.__new__, GroundTruth, TRUTH_FIELDS[:-1], 0)
    fresh.set_truth_record(object.__new__, GroundTruth, TRUTH_FIELDS, plant._plate_body)
    with pytest.raises(ValueError, match="set_truth_layout"):
        fresh.truth_record(0.0, *views)  # the copies' layout is still missing
    rotors = plant._rotors
    with pytest.raises(ValueError, match=r"^measured: expected"):
        rotors.truth_record(0.0, *views, (0, None))
    rotors.set_truth_record(object.__new__, GroundTruth, TRUTH_FIELDS, d.xpos.shape[0])
    with pytest.raises(IndexError, match="xmat"):
        rotors.truth_record(0.0, *views)
    rotors.set_truth_record(object.__new__, GroundTruth, TRUTH_FIELDS, plant._plate_body)
    with pytest.raises(ValueError, match="xmat"):
        rotors.truth_record(0.0, d.xpos, d.xquat, d.xmat[::2], d.qpos, d.qvel, d.subtree_com)
    with pytest.raises(TypeError):
        rotors.truth_record(
            0.0, d.xpos, d.xquat, d.xmat.astype(np.float32), d.qpos, d.qvel, d.subtree_com
        )
    # The plant's own record still works after all that on another core.
    assert math.isfinite(plant._ground_truth().time)


# ------------------------------------------------------------------ contact measurement
def test_cross3_equals_numpy_cross_bit_for_bit():
    rng = np.random.default_rng(9)
    specials = [0.0, -0.0, np.inf, -np.inf, np.nan, 5e-324, -1e308, 1e308, 1.0]
    for k in range(30_000):
        a = rng.standard_normal(3) * 10.0 ** rng.integers(-200, 200, size=3)
        b = rng.standard_normal(3) * 10.0 ** rng.integers(-200, 200, size=3)
        if k % 5 == 0:
            a[rng.integers(0, 3)] = specials[k % len(specials)]
        if k % 7 == 0:
            b[rng.integers(0, 3)] = specials[(k // 7) % len(specials)]
        with np.errstate(all="ignore"):
            got, want = _cross3(a, b), np.cross(a, b)
        assert got.dtype == want.dtype and got.shape == (3,)
        assert got.tobytes() == want.tobytes(), (a, b)


def _measures_equal(a: tuple, b: tuple) -> None:
    assert a[0] == b[0]
    for x, y in zip(a[1:], b[1:], strict=True):
        assert type(x) is type(y)
        if isinstance(x, np.ndarray):
            assert x.dtype == y.dtype and x.tobytes() == y.tobytes()
        else:
            assert struct.pack("<d", x) == struct.pack("<d", y)


def test_contact_measurement_equals_mujocos_contacts_when_perched():
    # Perched on the ceiling (4 plate contacts), pushed sideways and twisted (slip, yaw,
    # contacts thinning out), then released: twin plants, the Rust measurement on one, the
    # mj_contactForce derivation on the other.
    thrust = _perch_thrusts(4.0)
    plants = [_perch_plant(NoCeilingEffect()) for _ in range(2)]
    for p in plants:
        p.reset(base_position=(0.0, 0.0, 2.0 - 5e-4), thrusts=thrust)
        p.set_rotor_thrusts(thrust)
    fast, plain = plants
    seen = set()
    for k in range(900):
        for p in plants:
            if k == 200:
                p.apply_body_wrench("foot_plate", force=(0.0, 6.0, 0.0), torque=(0.0, 0.0, 1.5))
            if k == 500:
                p.apply_body_wrench("foot_plate", force=(0.0, 0.0, 0.0))
            if k == 700:
                p.set_rotor_thrusts(np.zeros(4))
            p.step(1)
        if k % 3 == 0:
            a = fast._tracker.measure_contacts(fast._fresh())
            c = measure_reference(plain._tracker, plain._fresh())
            _measures_equal(a, c)
            seen.add((a[0], a[5] != 0.0))
    assert {n for n, _ in seen} == {0, 1, 2, 3, 4}  # perched on 4 points .. released
    assert any(n > 0 and yaw for n, yaw in seen)  # twisted while in contact


def test_resting_on_other_links_takes_the_no_contact_numbers():
    """The stack's robot on the floor rests on its root and middle links, not the foot
    plate: contacts the measurement does not sum, so the core writes its numbers for an
    empty contact list, equal to the reference on a twin plant; a plate contact (perched on
    the ceiling) takes the tracker's measurement."""
    plants = []
    for _ in range(2):
        # awake throughout: this test is about the contacts of the resting robot, which a
        # sleeping robot does not have (rdm.plant.sleep)
        p = Plant("rdm", seed=0, ceiling_height=1.6, floor_height=0.0, sleep=False)
        p.reset(base_position=(0.0, 0.0, 0.12))
        plants.append(p)
    fast, plain = plants
    free = seen = 0
    for k in range(600):
        for p in plants:
            p.step(1)
        if k % 10 == 9:
            d = fast._fresh()
            plate = fast._tracker.plate_contact(d)
            with _free_records(fast) as calls:
                a = fast._ground_truth()
            free += sum(calls)
            _assert_same(a, ground_truth_reference(plain))
            if d.ncon and not plate:
                seen += 1
    assert seen > 40  # resting on the floor, the plate free
    assert free == 60 and fast._tracker.idle()

    perched = _perch_plant(NoCeilingEffect())
    twin = _perch_plant(NoCeilingEffect())
    for p in (perched, twin):
        p.reset(base_position=(0.0, 0.0, 2.0 - 5e-4), thrusts=_perch_thrusts(4.0))
        p.step(200)
    d = perched._fresh()
    assert d.ncon and perched._tracker.plate_contact(d)
    with _free_records(perched) as calls:
        a = perched._ground_truth()
    assert calls == [False] and a.foot_contact_points > 0
    _assert_same(a, ground_truth_reference(twin))
