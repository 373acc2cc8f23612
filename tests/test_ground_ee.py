"""``ee`` over the ground link: an end-effector target planned with rdm.planner on the
robot and handed to the node as a timed joint path (rdm.ground.ee), against the recording
fake node of test_ground_link."""

from __future__ import annotations

from concurrent.futures import Future

import numpy as np
from test_ground_link import FakeNode, datagram, make_port

from rdm.ground.ee import EePlanner


class _Now:
    """An executor that runs the plan at once (deterministic tests)."""

    def submit(self, fn, *a):
        f: Future = Future()
        f.set_result(fn(*a))
        return f


def test_ee_is_planned_and_handed_over_as_a_timed_joint_path() -> None:
    """A perched node at the planner's perched start: the ack is 'pending', the next tick
    hands the node one path starting at the tick's time and the present q, with no joint
    faster than 0.2 rad/s, ending with the end effector at the target (the model's forward
    kinematics, foot frame, within the planner's 1 mm); then the final ack is accepted."""
    from rdm.model import Robot
    from rdm.planner.core import PERCHED_START_Q

    node = FakeNode()
    node.status_value = {"flight_state": "armed", "perching": True}
    node.present_q = [*PERCHED_START_Q, 0.0, 0.0, 0.0, 0.0]
    port = make_port(node)
    port.planner = EePlanner("rdm", executor=_Now())
    target = [0.2, -0.3, -0.7]
    ack = port.handle(datagram("ee", {"position": target}, seq=3), None, 7.0)
    assert (ack["outcome"], ack["ack"]) == ("pending", 3)
    port.tick(7.5)
    [(name, points)] = node.calls
    assert name == "set_trajectory"
    times = np.array([t for t, _ in points])
    qs = np.array([q for _, q in points])
    assert times[0] == 7.5 and np.all(np.diff(times) > 0)
    assert qs[0].tolist() == node.present_q
    speed = np.abs(np.diff(qs, axis=0)) / np.diff(times)[:, None]
    assert speed.max() <= 0.2 + 1e-9
    frames = Robot.shipped("rdm").evaluate(list(qs[-1]))["frames"]
    ee = (np.linalg.inv(np.array(frames["foot"])) @ np.array(frames["end_effector"]))[:3, 3]
    assert np.linalg.norm(ee - target) < 1e-3
    assert port.outcomes == {"pending": 1, "accepted": 1}
    final = port.handle(datagram("ee", {"position": target}, seq=3), None, 7.6)  # a retry
    assert final["outcome"] == "accepted" and final["duplicate"] is True


def test_ee_refusals() -> None:
    """Not perched: not_perched; a plan that cannot reach: plan_failed naming the blocking
    constraint; a second ee while one is planned: busy. The node is never called."""

    class Unreached:
        reached, blocking, final_error = False, "joint_limit", 0.4

    node = FakeNode()
    port = make_port(node)
    port.planner = EePlanner("rdm", executor=_Now(), plan_fn=lambda t, q: Unreached())
    assert port.handle(datagram("ee", {"position": [0, 0, -1]}, seq=1), None, 0.0)["reason"] == (
        "not_perched"
    )
    node.status_value = {"perching": True}
    assert port.handle(datagram("ee", {"position": [0, 0, -1]}, seq=2), None, 0.0)["outcome"] == (
        "pending"
    )
    port.tick(0.1)
    final = port.verifier.senders["op"].ack
    assert final["reason"] == "plan_failed" and "joint_limit" in final["detail"]

    class Never:
        def submit(self, fn, *a):
            return Future()

    port.planner = EePlanner("rdm", executor=Never())
    assert port.handle(datagram("ee", {"position": [0, 0, -1]}, seq=3), None, 0.2)["outcome"] == (
        "pending"
    )
    port.tick(0.3)
    assert port.handle(datagram("ee", {"position": [0, 0, -1]}, seq=4), None, 0.4)["reason"] == (
        "busy"
    )
    assert node.calls == []
