"""Plant-side fast paths against their reference forms (docs/plant.md, "Ground truth, sensor
noise and their Rust cores"): the contact tracker's cached contact view, the array-wise contact
measurement, the bridge's foot-sensor read and the Neuron bank's change-counter refresh."""

from __future__ import annotations

import random

import can
import pytest
from float_bits import same_bits
from test_neuron_bank import SPECS, Bank

from rdm.plant import Plant


def _tracker_state(t) -> tuple:
    return (
        t._last_contact_time,
        None if t._anchor_pos is None else t._anchor_pos.tolist(),
        None if t._anchor_rot is None else t._anchor_rot.tolist(),
    )


def _landing_pair() -> tuple[Plant, Plant]:
    """Two identical plants on the floor; the second keeps the reference tracker update."""
    plants = []
    for _ in range(2):
        p = Plant("rdm", seed=5, ceiling_height=1.6, floor_height=0.0)
        p.reset(base_position=(0.0, 0.0, 0.05))
        plants.append(p)
    fast, plain = plants
    plain._tracker.update = plain._tracker.update_plain  # the reference path for this plant
    return fast, plain


def _measuresame_bits(a: tuple, b: tuple) -> None:
    assert a[0] == b[0]
    for x, y in zip(a[1:], b[1:], strict=True):
        assert same_bits(x, y)


def test_contact_tracker_and_measurement_equal_the_reference_through_contact_changes():
    fast, plain = _landing_pair()
    plants = (fast, plain)
    ncons = set()
    anchors = set()
    for k in range(1300):
        if k == 150:  # lift off: contacts thin out, then release after 0.1 s
            for p in plants:
                p.set_rotor_thrusts([9.0, 9.5, 9.0, 9.5])
        if k == 600:  # fall back: a new anchor
            for p in plants:
                p.set_rotor_thrusts([0.0, 0.0, 0.0, 0.0])
        for p in plants:
            p.step(1)
        ncons.add(fast._data.ncon)
        assert _tracker_state(fast._tracker) == _tracker_state(plain._tracker), k
        anchors.add(fast._tracker._anchor_pos is not None)
        if k % 7 == 0:
            a = fast._tracker.measure_contacts(fast._fresh())
            b = plain._tracker.measure_plain(plain._fresh())
            _measuresame_bits(a, b)
            assert _tracker_state(fast._tracker) == _tracker_state(plain._tracker), k
    assert len(ncons) > 2 and 0 in ncons  # several contact counts, and flight
    assert anchors == {True, False}
    assert fast._tracker.view_misses == 0


def test_a_moved_contact_list_is_detected_and_reread():
    fast, plain = _landing_pair()
    for _ in range(5):
        fast.step(1)
        plain.step(1)
    tracker = fast._tracker
    data, ncon, addr, view = tracker._geom_view
    assert ncon == fast._data.ncon > 0 and data is fast._data
    tracker._geom_view = (data, ncon, addr + 8, view)  # pretend the list moved
    tracker.measure_contacts(fast._fresh())
    assert tracker.view_misses == 1 and tracker._geom_view[0] is None
    plain._tracker.measure_plain(plain._fresh())
    fast.step(1)
    plain.step(1)
    assert _tracker_state(tracker) == _tracker_state(plain._tracker)


def test_bridge_wrench_read_equals_the_reference_reading():
    pair = []
    for _ in range(2):
        p = Plant("rdm", seed=9, ceiling_height=1.2, floor_height=0.0)
        p.reset(base_position=(0.0, 0.0, 0.6), thrusts=[4.0, 4.5, 5.0, 4.2])
        p.set_rotor_thrusts([5.0, 3.0, 6.0, 4.0])
        pair.append(p)
    fast, plain = pair
    for step in range(300):
        fast.step(1)
        plain.step(1)
        for key in fast.wrench_models:
            force, torque = fast.wrench_force_torque(key)
            ref = plain.wrench_plain(key)
            assert same_bits(force, ref.force) and same_bits(torque, ref.torque), (step, key)
    for p in pair:
        with pytest.raises(ValueError, match="unknown wrench sensor 'nope'"):
            p.wrench_force_torque("nope")
        with pytest.raises(ValueError, match="unknown wrench sensor 'nope'"):
            p.wrench_plain("nope")


def test_bank_change_counters_follow_the_core_on_random_frames():
    twin = Bank(SPECS)
    rng = random.Random(4)
    bank = twin.bank
    moved = 0
    try:
        last = None
        for ms in range(400):
            for _ in range(rng.randrange(3)):
                can_id = rng.choice([0x000, 0x001, 0x0E0, 0x111, 0x112, 0x135, 0x1F7, 0x7FF])
                data = bytes(rng.randrange(256) for _ in range(rng.randrange(9)))
                twin.send(can.Message(arbitration_id=can_id, data=data, is_extended_id=False))
            twin.tick(ms * 0.001)
            now = [b.changes[0] for b in bank.boards]
            assert now == bank._core.changes(), ms
            if now != last and last is not None:
                moved += 1
            last = now
            if ms % 50 == 0:
                value = rng.randrange(1000)
                bank.boards[1].esc.held_value = value  # bumps a counter
                assert [b.changes[0] for b in bank.boards] == bank._core.changes()
    finally:
        twin.close()
    assert moved > 0
