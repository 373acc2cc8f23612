"""The static push ceiling (rdm.scenarios.push_ceiling) against a closed form: for a force in
the arm's plane (x, z of the end effector in the hanging posture) pushed and pulled with the
foot rotors at full spare thrust, each contact condition is a bound a <= k P / (|c| + k |c_z|)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from rdm.model import Robot
from rdm.scenarios import push_ceiling
from rdm.scenarios.perching import PERCH_POSTURE, leveled


@pytest.fixture(scope="module")
def robot():
    return Robot.default()


def _closed_form(robot, q6, axis: int) -> float:
    o = robot.evaluate(leveled(np.asarray(q6, float), robot.n_q))
    mg = o["mass"] * push_ceiling.GRAVITY
    hover = np.linalg.lstsq(np.asarray(o["allocation_bar"]), [mg, 0, 0, 0], rcond=None)[0]
    spare = sum(r["thrust_max"] - h for r, h in zip(robot.rotors[:2], hover[:2], strict=True))
    ee = np.asarray(o["frames"]["end_effector"])
    e = ee[:3, axis]
    m = np.cross(ee[:3, 3], e)
    bounds = []
    for c, k in (
        (e[0], 0.9),
        (e[1], 0.9),
        (m[2], 0.5),
        (m[1], push_ceiling.QP_HALF[0]),
        (m[0], push_ceiling.QP_HALF[1]),
    ):
        den = abs(c) + k * abs(e[2])
        if den > 0:  # a row the force does not load bounds nothing
            bounds.append(k * spare / den)
    if abs(e[2]) > 0:
        bounds.append((spare - 8.0) / abs(e[2]))
    return min(bounds)


@pytest.mark.parametrize("axis", [0, 2])
def test_planar_axes_match_the_closed_form(robot, axis):
    lp = push_ceiling.ceiling(robot, PERCH_POSTURE)
    # rel 1e-3: q1 = 1.5708 is not exactly pi/2, so the foot rotors have a tiny M_y lever
    # (the closed form takes it as 0; the LP may use it)
    assert lp[axis] == pytest.approx(_closed_form(robot, PERCH_POSTURE, axis), rel=1e-3)


def test_end_effector_axes_are_a_rotation_and_y_is_at_least_the_symmetric_bound(robot):
    o = robot.evaluate(leveled(np.asarray(PERCH_POSTURE, float), robot.n_q))
    rot = np.asarray(o["frames"]["end_effector"])[:3, :3]
    assert Rotation.from_matrix(rot).magnitude() >= 0.0  # scipy accepts it as a rotation
    assert np.allclose(rot.T @ rot, np.eye(3), atol=1e-9)
    lp = push_ceiling.ceiling(robot, PERCH_POSTURE)
    # y: the LP may also use a thrust difference between the foot rotors (a roll moment)
    assert lp[1] >= _closed_form(robot, PERCH_POSTURE, 1) - 1e-9


def test_any_controller_ceiling_is_higher_and_bad_model_is_refused(robot):
    perch = push_ceiling.ceiling(robot, PERCH_POSTURE)
    anyc = push_ceiling.ceiling(robot, PERCH_POSTURE, model="all", epsilon_z=0.0)
    assert np.all(anyc >= perch)
    with pytest.raises(ValueError, match="model"):
        push_ceiling.ceiling(robot, PERCH_POSTURE, model="foo")
