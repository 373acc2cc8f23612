"""Every joint command path of the onboard node refuses a goal outside the joint limits of the
shipped URDF (read here with ElementTree, not through the model) and takes one just inside:
``set_joint_targets``, ``set_trajectory`` (a planner's points), ``move_joints`` (the operator's
jerk-limited motion) and the ground link's ``joints`` command. A refusal names the joint, the
value and the limit, is one log line and is counted ``joint_targets_invalid``.

The goals sit 1 mrad either side of a limit: a flipped comparison refuses the one inside, a
limit read from the wrong side (lower for upper) refuses both (the arm's limits are symmetric,
so a swapped pair makes every goal outside), a missing check takes the one outside. The
perching sequence's own goals (q1 = 1.5708, 3.7e-6 rad past the URDF's 1.57079632679, inside
the node's 1e-5 rad slack) are taken.
"""

from __future__ import annotations

import logging
from collections.abc import Callable

import numpy as np
import pytest
from fed_byte_link import FedByteLink
from urdf_limits import urdf_limits

from rdm.ground import commands
from rdm.ground.message import Reason, Rejected
from rdm.nodes.onboard import OnboardNode
from rdm.scenarios.perching import PERCH_POSTURE, PERCHED_MOTION
from rdm.scenarios.push_plan import PERCHED_POSTURE

STEP = 1e-3  # rad either side of a limit


def _goal(node: OnboardNode, joint: str, value: float) -> np.ndarray:
    """The full joint_order vector: zeros, ``joint`` at ``value``."""
    q = np.zeros(node.robot.n_q)
    q[list(node.robot.joint_names).index(joint)] = value
    return q


def _set_joint_targets(node: OnboardNode, q: np.ndarray) -> bool:
    return node.set_joint_targets(q.tolist())


def _set_trajectory(node: OnboardNode, q: np.ndarray) -> bool:
    return node.set_trajectory([(0.0, np.zeros(q.size).tolist()), (1.0, q.tolist())])


def _move_joints(node: OnboardNode, q: np.ndarray) -> bool:
    return node.move_joints(q.tolist()) is None


def _ground_joints(node: OnboardNode, q: np.ndarray) -> bool:
    try:
        commands.apply(node, "joints", {"q": q.tolist()})
    except Rejected as exc:
        assert exc.reason is Reason.REFUSED
        return False
    return True


def _taken(node: OnboardNode, q: np.ndarray) -> bool:
    """The node's joint goal is ``q``: its targets, or its trajectory's last point."""
    if node._trajectory is not None:
        return bool(np.array_equal(node._trajectory[1][-1], q))
    return node.joint_targets is not None and bool(np.array_equal(node.joint_targets, q))


PATHS: dict[str, Callable[[OnboardNode, np.ndarray], bool]] = {
    "set_joint_targets": _set_joint_targets,
    "set_trajectory": _set_trajectory,
    "move_joints": _move_joints,
    "ground joints": _ground_joints,
}
CASES = [("q2", "upper"), ("q5", "lower"), ("beta1", "upper"), ("alpha2", "lower")]


@pytest.mark.parametrize("path", list(PATHS))
@pytest.mark.parametrize(("joint", "side"), CASES)
def test_a_goal_just_outside_a_limit_is_refused_and_just_inside_taken(
    path: str, joint: str, side: str, caplog: pytest.LogCaptureFixture
) -> None:
    lo, hi = urdf_limits()[joint]
    limit, outward = (hi, 1.0) if side == "upper" else (lo, -1.0)
    node = OnboardNode(FedByteLink())
    send = PATHS[path]

    outside = _goal(node, joint, limit + outward * STEP)
    with caplog.at_level(logging.WARNING, logger="rdm.onboard"):
        assert not send(node, outside)
    assert node.counts["joint_targets_invalid"] == 1
    assert node.joint_targets is None and node._trajectory is None
    lines = [r.getMessage() for r in caplog.records if r.name == "rdm.onboard"]
    assert len(lines) == 1
    assert f"joint {joint} = {limit + outward * STEP!r} rad" in lines[0]
    assert f"{side} limit {limit!r} rad" in lines[0]

    inside = _goal(node, joint, limit - outward * STEP)
    assert send(node, inside)
    assert _taken(node, inside)
    assert node.counts["joint_targets_invalid"] == 1


def test_the_ground_operator_reads_the_refusal() -> None:
    lo, _ = urdf_limits()["q1"]
    node = OnboardNode(FedByteLink())
    q = np.zeros(6)
    q[0] = lo - 0.2
    with pytest.raises(Rejected) as exc:
        commands.apply(node, "joints", {"q": q.tolist()})
    assert exc.value.detail == (
        f"move_joints(): joint q1 = {lo - 0.2!r} rad below its lower limit {lo!r} rad"
    )


def test_a_trajectory_with_one_point_outside_is_refused_whole() -> None:
    _, hi = urdf_limits()["q6"]
    node = OnboardNode(FedByteLink())
    kept = [(0.0, [0.0] * node.robot.n_q), (1.0, [0.1] * node.robot.n_q)]
    assert node.set_trajectory(kept)
    middle = _goal(node, "q6", hi + STEP).tolist()
    points = [(0.0, [0.0] * node.robot.n_q), (0.5, middle), (1.0, [0.0] * node.robot.n_q)]
    assert not node.set_trajectory(points)
    assert node.counts["joint_targets_invalid"] == 1
    assert node._trajectory[1].tolist() == [p[1] for p in kept]  # the earlier one kept


@pytest.mark.parametrize(
    "posture", [PERCH_POSTURE, PERCHED_POSTURE, *(q for _, q in PERCHED_MOTION)]
)
def test_the_perching_sequence_goals_are_taken(posture: tuple[float, ...]) -> None:
    limits = urdf_limits()
    node = OnboardNode(FedByteLink())
    names = list(node.robot.joint_names)
    for j, v in enumerate(posture):
        lo, hi = limits[names[j]]
        assert lo - 1e-5 <= v <= hi + 1e-5
    assert node.move_joints(list(posture)) is None
    assert node.counts["joint_targets_invalid"] == 0
