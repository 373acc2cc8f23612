"""The lockstep hover (``rdm sim hover``'s scenario, every byte on its wire) of robots given by
file with six and eight rotors: the MuJoCo ground truth holds the hover scenario's own bounds,
and every rotor's ESC carries part of the weight."""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
import pytest

from rdm.scenarios import hover
from rdm.scenarios.common import truth_arrays

ROBOTS = Path(__file__).parent / "data" / "robots"


@pytest.mark.parametrize(("name", "rotors"), [("hexa", 6), ("octo", 8)])
def test_robot_from_file_hovers_in_lockstep(tmp_path, name, rotors):
    """Catches a count stuck at 4 anywhere on the way (Spinal's ESC outputs, the Neuron
    bank, the plant: a rotor that never spins or the build failing), a gain row sent to the
    wrong rotor (the hover tips) and an allocation column in the wrong place."""
    result = hover.run(tmp_path, robot=str(ROBOTS / name / f"{name}.toml"))
    try:
        failed = [(m.name, m.ours) for m in result.metrics if not m.passed]
        assert not failed, failed
        stack = result.stack
        assert stack.spinal.core.motor_number == rotors
        assert len(stack.spinal.duties) == rotors
        a = truth_arrays(stack)
        assert a["thrust"].shape[1] == rotors
        window = a["t"] >= a["t"][-1] - 2.0
        mean = a["thrust"][window].mean(axis=0)
        # every ESC drives its rotor (above the 1 N thrust_min some of the time) and the sum
        # carries the weight (the CoG holds its height: the scenario's metric above)
        assert (a["thrust"][window].max(axis=0) > 1.0).all(), mean
        mass = mujoco.mj_getTotalmass(stack.plant.model)
        np.testing.assert_allclose(mean.sum(), mass * 9.80665, rtol=0.1)
    finally:
        result.stack.close()
