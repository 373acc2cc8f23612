"""Checks shared by the task scenario tests (tests/test_scenario_tasks.py,
tests/test_scenario_painting.py): metric rows by name, and the perch kept during the task
from MuJoCo's ground truth."""

from __future__ import annotations

import numpy as np

from rdm.scenarios.common import truth_arrays


def metrics_of(res) -> dict[str, float]:
    """Our value of every metric row of a scenario result, by name."""
    return {m.name: m.ours for m in res.metrics}


def perch_ok(res) -> None:
    """The foot stays on the ceiling (truth contact at every sample) and does not slide."""
    a = truth_arrays(res.stack)
    t_perch = res.facts["t_perch"]
    assert t_perch is not None, "never perched"
    assert res.facts["final_phase"] == "hold"
    held = a["t"] >= t_perch + 0.5
    assert a["t"][held][-1] >= res.facts["t_task_end"], "the run ended before the task"
    assert a["contact"][held].all(), "the foot left the ceiling during the task"
    slip = a["slip"][held]
    assert np.max(np.linalg.norm(slip - slip[0], axis=1)) < 1e-3  # < 1 mm
    assert abs(a["foot"][held, 2].mean() - 1.6) < 0.01  # at the ceiling
    # only the tool touched the objects (no arm link pushed on them)
    assert metrics_of(res)["ticks with a robot link (not the tool) touching an object"] == 0
