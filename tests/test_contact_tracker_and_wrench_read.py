"""The foot contact tracker's first-contact anchor and measurement, and the bridge's 1 kHz
foot-sensor reads.

Oracles: the anchor rule applied to MuJoCo's own contact list (``data.contact.geom`` and
``model.geom_bodyid``), the measurement derived from MuJoCo's contact objects and
``mj_contactForce`` (``truth_reference.measure_reference``), the wrench noise model's numpy
array form on MuJoCo's ideal sensor values with numpy's generator called once per sample."""

from __future__ import annotations

import math

import numpy as np
import pytest
from float_bits import same_bits
from truth_reference import measure_reference

from rdm.plant import Plant
from rdm.plant.sensors import LEPTRINO_FULL_SCALE_COUNTS


class _AnchorOracle:
    """The anchor rule on MuJoCo's contact list: a contact touching a plate geom stamps the
    time and, with no anchor, anchors the plate's pose; otherwise the anchor is released once
    the last stamp is more than ``release_time`` old."""

    def __init__(self, plant: Plant) -> None:
        m = plant.model
        self.plate = plant._tracker._plate_body
        self.plate_geoms = {g for g in range(m.ngeom) if m.geom_bodyid[g] == self.plate}
        self.release = plant._tracker.release_time
        self.last = -math.inf
        self.anchor: tuple | None = None

    def observe(self, data, in_contact: bool | None = None) -> None:
        if in_contact is None:
            pairs = data.contact.geom[: data.ncon].ravel().tolist()
            in_contact = any(g in self.plate_geoms for g in pairs)
        if in_contact:
            self.last = float(data.time)
            if self.anchor is None:
                self.anchor = (
                    data.xpos[self.plate].tolist(),
                    data.xmat[self.plate].reshape(3, 3).tolist(),
                )
        elif float(data.time) - self.last > self.release:
            self.last, self.anchor = -math.inf, None

    def state(self) -> tuple:
        return (self.last, self.anchor)


def _tracker_state(t) -> tuple:
    anchor = None if t.anchor_pos is None else (t.anchor_pos.tolist(), t.anchor_rot.tolist())
    return (t.last_contact_time, anchor)


def _landing_plant() -> Plant:
    plant = Plant("rdm", seed=5, ceiling_height=1.6, floor_height=0.0)
    plant.reset(base_position=(0.0, 0.0, 0.05))
    return plant


def _measures_same_bits(a: tuple, b: tuple) -> None:
    assert a[0] == b[0]
    for x, y in zip(a[1:], b[1:], strict=True):
        assert same_bits(x, y)


def test_contact_anchor_and_measurement_follow_mujocos_contacts_through_contact_changes():
    plant = _landing_plant()
    tracker = plant._tracker
    oracle = _AnchorOracle(plant)
    ncons = set()
    anchors = set()
    for k in range(1300):
        if k == 150:  # lift off: contacts thin out, then release after 0.1 s
            plant.set_rotor_thrusts([9.0, 9.5, 9.0, 9.5])
        if k == 600:  # fall back: a new anchor
            plant.set_rotor_thrusts([0.0, 0.0, 0.0, 0.0])
        plant.step(1)
        oracle.observe(plant._data)
        ncons.add(plant._data.ncon)
        assert _tracker_state(tracker) == oracle.state(), k
        anchors.add(oracle.anchor is not None)
        if k % 7 == 0:
            d = plant._fresh()
            a = tracker.measure_contacts(d)
            oracle.observe(d, a[0] > 0)
            assert _tracker_state(tracker) == oracle.state(), k
            _measures_same_bits(a, measure_reference(tracker, d))
    assert len(ncons) > 2 and 0 in ncons  # several contact counts, and flight
    assert anchors == {True, False}
    assert tracker.view_misses == 0


def test_a_moved_contact_list_is_detected_and_reread():
    plant = _landing_plant()
    oracle = _AnchorOracle(plant)
    for _ in range(5):
        plant.step(1)
        oracle.observe(plant._data)
    tracker = plant._tracker
    core, data, ncon = tracker._core, plant._data, plant._data.ncon
    view = core.view_of(data, ncon)
    assert ncon > 0 and view is not None
    core.keep_view(data, ncon, core.view_address + 8, view)  # pretend the list moved
    points = tracker.measure_contacts(plant._fresh())[0]
    oracle.observe(plant._data, points > 0)
    assert tracker.view_misses == 1 and core.view_of(data, ncon) is None
    plant.step(1)
    oracle.observe(plant._data)
    assert _tracker_state(tracker) == oracle.state()


def test_the_tracker_core_refuses_bad_input_with_one_line():
    """A negative or NaN release time and a geom view that is not (n, 2) pairs are refused
    with a ValueError naming the argument; the refused release time leaves the old one."""
    from rdm._rdm import FootTrackerCore

    for bad in (-0.1, math.nan):
        with pytest.raises(ValueError, match=r"^release_time: must be >= 0"):
            FootTrackerCore([1, 2], bad)
    core = FootTrackerCore([1, 2], 0.1)
    with pytest.raises(ValueError, match=r"^release_time"):
        core.release_time = -1.0
    assert core.release_time == 0.1
    with pytest.raises(ValueError, match=r"^geom: expected \(n, 2\)"):
        core.keep_view(object(), 1, 0, np.zeros((1, 3), dtype=np.int32))
    assert core.idle() and core.view_address is None


def _wrench_reference(plant: Plant, key: str, rng: np.random.Generator) -> np.ndarray:
    """The noisy wrench in numpy: MuJoCo's ideal values, six normals of one generator call,
    clipped at the rated capacity and quantised to rated / 10000."""
    model = plant.wrench_models[key]
    force, torque = plant.wrench_ideal(key)
    noise = model.noise
    w = np.concatenate([force, torque]) + np.asarray(noise.bias, dtype=float)
    w = w + noise.noise_fraction_of_rated * model.rated * rng.normal(0.0, 1.0, 6)
    w = np.clip(w, -model.rated, model.rated)
    lsb = model.rated / LEPTRINO_FULL_SCALE_COUNTS
    return np.round(w / lsb) * lsb


def test_bridge_wrench_reads_equal_the_array_form_of_the_ideal_values():
    plant = Plant("rdm", seed=9, ceiling_height=1.2, floor_height=0.0)
    plant.reset(base_position=(0.0, 0.0, 0.6), thrusts=[4.0, 4.5, 5.0, 4.2])
    plant.set_rotor_thrusts([5.0, 3.0, 6.0, 4.0])
    keys = list(plant.wrench_models)
    seeds = np.random.SeedSequence(9).spawn(1 + len(keys))
    rngs = {k: np.random.default_rng(s) for k, s in zip(keys, seeds[1:], strict=True)}
    for step in range(300):
        plant.step(1)
        for key in keys:
            if step % 2:
                reading = plant.wrench(key)
                force, torque = reading.force, reading.torque
            else:
                values = plant.wrench_values(key)
                assert type(values) is tuple and all(type(v) is float for v in values)
                force, torque = values[:3], values[3:]
            want = _wrench_reference(plant, key, rngs[key])
            assert same_bits(force, want[:3]) and same_bits(torque, want[3:]), (step, key)
    with pytest.raises(ValueError, match="unknown wrench sensor 'nope'"):
        plant.wrench("nope")
    with pytest.raises(ValueError, match="unknown wrench sensor 'nope'"):
        plant.wrench_values("nope")
