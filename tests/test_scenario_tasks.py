"""Perching manipulation tasks (Fig. 14) end to end: outcomes from MuJoCo's ground truth
(tool contacts, valve hinge, foot contact and slip), not from the controller's estimates."""

from __future__ import annotations

import math

import numpy as np
import pytest

from rdm.scenarios import tasks
from rdm.scenarios.common import truth_arrays


def _perch_ok(res) -> None:
    a = truth_arrays(res.stack)
    t_perch = res.facts["t_perch"]
    assert t_perch is not None, "never perched"
    held = a["t"] >= t_perch + 0.5
    assert a["contact"][held].all(), "the foot left the ceiling during the task"
    slip = a["slip"][held]
    assert np.max(np.linalg.norm(slip - slip[0], axis=1)) < 1e-3  # < 1 mm
    assert abs(a["foot"][held, 2].mean() - 1.6) < 0.01  # at the ceiling


@pytest.fixture(scope="module")
def drilling(tmp_path_factory):
    return tasks.run_task("drilling", tmp_path_factory.mktemp("drilling"), log=False)


@pytest.fixture(scope="module")
def valve(tmp_path_factory):
    return tasks.run_task("valve", tmp_path_factory.mktemp("valve"), log=False)


def test_drilling_touches_every_target_and_keeps_the_perch(drilling):
    res = drilling
    errs = res.facts["hole_errors_m"]
    assert len(errs) == len(tasks.DRILL_TARGETS)
    assert all(e is not None and math.isfinite(e) for e in errs), "a target was never touched"
    assert max(errs) < 0.02  # paper: about 0.01 m
    _perch_ok(res)


def test_drilling_presses_with_a_real_force(drilling):
    m = {x.name: x.ours for x in drilling.metrics}
    assert m["mean drilling force (contact, truth)"] > 1.0


def test_valve_turns_and_the_wrist_sensor_sees_the_moment(valve):
    m = {x.name: x.ours for x in valve.metrics}
    assert m["valve angle turned"] > 30.0  # degrees of the hinge (truth)
    # the stem's dry friction alone is 0.15 N m: the EE must apply at least that
    assert m["peak |M_x| at the EE sensor while turning (truth)"] > 0.1
    _perch_ok(valve)
