"""The perched weight share (``ControlPipeline.set_perch_weight_share``,
``ModelTerms.perch_unload``): the rotors' wrench with the share handed to the contact, checked
from the model's rotor positions and directions (eqs. 8-9 written with numpy, drag included)
instead of the allocation the pipeline solves with; the share's bounds and counters; the node
adding it to the perched feed-forward only."""

from __future__ import annotations

import numpy as np
import pytest
from onboard_rig import Rig

from rdm.model import Robot
from rdm.nodes.onboard import OnboardNode
from rdm.nodes.onboard_config import OnboardConfig
from rdm.nodes.onboard_control import PERCH_WEIGHT_SHARE_MAX, ControlPipeline
from rdm.nodes.onboard_monitors import MonitorLimits
from rdm.scenarios import wall_perching as wp

pytestmark = pytest.mark.timeout(300)

ROBOT = Robot.default()
G = 9.80665


def _rotor_wrench(q: np.ndarray, thrust: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Force, moment about the CoG (foot axes) of ``thrust`` from rotor positions/directions
    and drag torques; the CoG in the foot frame."""
    o = ROBOT.evaluate(q)
    p, u = np.asarray(o["rotor_positions"]), np.asarray(o["rotor_directions"])
    cog = np.linalg.inv(np.asarray(o["foot_in_cog"]))[:3, 3]
    c = np.array([r["drag_to_thrust"] for r in ROBOT.rotors])
    sigma = np.array([r["spin"] for r in ROBOT.rotors])
    per_rotor = np.cross(p - cog, u) - (c * sigma)[:, None] * u
    return u.T @ thrust, per_rotor.T @ thrust, cog


@pytest.mark.parametrize(
    ("params", "beta1"),
    [({}, 0.0), (wp.PERCH_PARAMS, wp.WALL_BETA1)],
    ids=["ceiling", "wall"],
)
@pytest.mark.parametrize("share", [0.05, 0.1, 0.3])
def test_unloaded_thrust_balances_weight_with_friction_at_the_contact(params, beta1, share):
    pipe = ControlPipeline(ROBOT, OnboardConfig(perch_params=dict(params)))
    q = np.zeros(ROBOT.n_q)
    q[7] = beta1
    assert pipe.update_model(q)
    t = pipe.terms
    thrust = t.hover_thrust + share * t.perch_unload
    force, moment, cog = _rotor_wrench(q, thrust)
    weight = t.mass * G
    center = np.asarray(params.get("contact_center", [0.0, 0.0, 0.0]))
    friction = np.array([0.0, 0.0, share * weight])  # up, at the contact centre
    # vertical: rotors + friction carry the weight
    assert force[2] + friction[2] == pytest.approx(weight, rel=1e-9)
    # no moment about the CoG from rotors and friction together (the attitude is untouched)
    total = moment + np.cross(center - cog, friction)
    np.testing.assert_allclose(total, 0.0, atol=1e-9 * weight)
    # scaling the hover thrust by 1 - share instead would leave friction's moment, ~0.5 m x it
    off = np.cross(center - cog, friction) + _rotor_wrench(q, (1 - share) * t.hover_thrust)[1]
    assert np.abs(off).max() > 0.5 * abs(center[0] - cog[0]) * share * weight


def test_share_bounded_and_counted():
    pipe = ControlPipeline(ROBOT, OnboardConfig())
    pipe.set_perch_weight_share(0.2)
    assert pipe.perch_weight_share == 0.2
    pipe.set_perch_weight_share(float("nan"))
    assert pipe.perch_weight_share == 0.2 and pipe.counts["perch_weight_share_refused"] == 1
    pipe.set_perch_weight_share(2.0)
    assert pipe.perch_weight_share == PERCH_WEIGHT_SHARE_MAX
    pipe.set_perch_weight_share(-0.1)
    assert pipe.perch_weight_share == 0.0 and pipe.counts["perch_weight_share_clipped"] == 2


def test_node_adds_the_share_to_the_perched_feed_forward_only():
    from test_onboard_perch import fly, raw_of, start

    rig = Rig(
        lambda uart, f: OnboardNode(
            uart, f, ROBOT, config=OnboardConfig(monitors=MonitorLimits(joint_tracking_rad=7.0))
        ),
        foot=True,
    )
    try:
        rig.foot_raw = raw_of([0.0, 0.0, 10.0, 0.0, 0.0, 0.0])
        t = start(rig)
        ctl = rig.node.control
        ctl.set_perch_weight_share(0.2)  # flying: no effect
        t = fly(rig, t, t + 0.1)
        flying = rig.node.last_command.flight_thrust.copy()
        ctl.set_perch_weight_share(0.0)
        t = fly(rig, t, t + 0.1)
        np.testing.assert_allclose(rig.node.last_command.flight_thrust, flying, atol=1e-6)
        rig.node.request_perch(True)
        t = fly(rig, t, t + 0.2)
        held = rig.node.last_command.flight_thrust.copy()
        ctl.set_perch_weight_share(0.2)
        t = fly(rig, t, t + 0.1)
        shed = rig.node.last_command.flight_thrust
        np.testing.assert_allclose(shed - held, 0.2 * ctl.terms.perch_unload, atol=1e-9)
        assert np.sum(shed) < np.sum(held) - 0.1 * ctl.terms.mass * G
    finally:
        rig.close()
