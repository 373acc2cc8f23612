"""``OnboardConfig.rp_integration_hold_rate``: Spinal's roll/pitch integration is stopped while
the fold of the hanging scenarios turns the IMU (root) link against the CoG frame and restarted
after it. Checked against MuJoCo's own q1 (the joint that turns the root link against the
foot) and Spinal's integral, in two short lockstep runs (13.1 s simulated: climb, fold, hover,
``log=False``, ~5 s wall each), one with the option and one without."""

from __future__ import annotations

import numpy as np
import pytest

from rdm.nodes.onboard_config import OnboardConfig
from rdm.scenarios import perching
from rdm.scenarios import perching_foot_at_plate as fp

pytestmark = pytest.mark.timeout(300)

#: A fold joint rate [rad/s] MuJoCo must show before Spinal may be required not to integrate
#: (the scenario's fold averages 0.2 rad/s); the option's threshold below it.
MOVING = 0.05
HOLD_RATE = 0.02
#: Latency allowed between MuJoCo's joint motion and Spinal's flag: the 0.1 s rate window,
#: the reported-angle lag and one UART hop.
LATENCY_S = 0.3


def _run(tmp_path, hold_rate):
    rec: dict[str, list] = {"t": [], "q1": [], "integrating": [], "ei": []}

    def watch(stack, now: float) -> None:
        m, d = stack.plant.model, stack.plant.data
        q1_name = stack.onboard.control.robot.joint_names[0]
        rec["t"].append(now)
        rec["q1"].append(float(d.qpos[m.jnt_qposadr[m.joint(q1_name).id]]))
        rec["integrating"].append(bool(stack.spinal.core.integrating))
        rec["ei"].append(float(stack.spinal.core.error_integral[1]))

    onboard = perching.onboard_config(
        perch_params=dict(fp.TABLE_VII_PARAMS), rp_integration_hold_rate=hold_rate
    )
    res = fp.run(tmp_path, duration=13.1, log=False, motion=(), observer=watch, onboard=onboard)
    return res, {k: np.asarray(v) for k, v in rec.items()}


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    held = _run(tmp_path_factory.mktemp("held"), HOLD_RATE)
    plain = _run(tmp_path_factory.mktemp("plain"), None)
    return held, plain


def _moving(r: dict) -> np.ndarray:
    """Ticks where MuJoCo's q1 turns faster than MOVING (central differences)."""
    return np.abs(np.gradient(r["q1"], r["t"])) > MOVING


def test_no_integration_while_mujoco_q1_moves(runs):
    """Bugs caught: 161 never sent (Spinal integrates through the fold); the rate taken
    from a fixed model (no change seen); the threshold compared the wrong way round."""
    (_, r), _ = runs
    moving = _moving(r)
    assert moving.sum() > 300  # the fold: several seconds of q1 motion
    t_start, t_end = r["t"][moving][[0, -1]]
    inside = (r["t"] > t_start + LATENCY_S) & (r["t"] < t_end - LATENCY_S) & moving
    assert inside.sum() > 300
    assert not r["integrating"][inside].any()


def test_integration_restarts_after_the_fold(runs):
    """Bug caught: 160 never re-sent after the hold (the integral stays frozen for good)."""
    (res, r), _ = runs
    t_end = r["t"][_moving(r)][-1]
    after = r["t"] > t_end + LATENCY_S
    assert after.sum() > 50
    assert r["integrating"][after].all()
    assert res.stack.onboard.counts["rp_integration_held"] >= 1
    assert res.stack.onboard.counts["rp_integration_resumed"] >= 1


def test_the_fold_no_longer_winds_the_pitch_integral(runs):
    """Without the option the fold leaves ~0.5 rad s in Spinal's pitch integral
    (docs/scenarios.md, "Where the integral comes from"); with it, the integral gathered
    from the start of q1's motion to the end of the run stays small. Bug caught: a hold
    that starts only after most of the fold."""
    (_, held), (_, plain) = runs
    start = plain["t"][_moving(plain)][0]
    gained_plain = plain["ei"][-1] - plain["ei"][plain["t"] >= start][0]
    start = held["t"][_moving(held)][0]
    gained_held = held["ei"][-1] - held["ei"][held["t"] >= start][0]
    assert gained_plain > 0.3
    assert abs(gained_held) < 0.1 * gained_plain


def test_rate_must_be_positive():
    """Bad input: a zero, negative or non-finite rate is refused with the field's name."""
    for bad in (0.0, -1.0, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="rp_integration_hold_rate"):
            OnboardConfig(rp_integration_hold_rate=bad)


def test_scenario_threshold_is_above_one_encoder_count_per_window():
    """The hanging scenarios' threshold (``perching.RP_INTEGRATION_HOLD_RATE``) lies above
    the rate one Dynamixel count (2 pi / 4096) over the node's window reads as, and below the
    fold's mean q1 rate (PERCH_POSTURE's q1 over RECONFIGURE_S). Bugs caught: a threshold a
    still servo's count flicker crosses; one the fold never crosses."""
    from rdm.nodes.onboard_config import RP_HOLD_WINDOW_S

    one_count = 2.0 * np.pi / 4096 / RP_HOLD_WINDOW_S
    fold_mean = perching.PERCH_POSTURE[0] / perching.RECONFIGURE_S
    rate = perching.RP_INTEGRATION_HOLD_RATE
    assert one_count < rate < 0.2 * fold_mean
    assert perching.onboard_config().rp_integration_hold_rate == rate


def test_hold_is_off_where_it_made_the_run_worse():
    """Drilling and the paper-posture perching (``perching_foot_at_plate``, where the integral
    wound up during the fold presses the plate onto one edge) fly with the hold; the valve and
    the two paintings do not (docs/scenarios.md, "Where the integral comes from"). Bug caught:
    a task flown with the perching default, or the paper-posture perching flown without it."""
    from rdm.scenarios import tasks

    assert tasks.task_onboard_config("drilling").rp_integration_hold_rate == HOLD_RATE
    for task in ("valve", "painting", "painting-panel"):
        assert tasks.task_onboard_config(task).rp_integration_hold_rate is None
    assert fp.RP_INTEGRATION_HOLD_RATE == HOLD_RATE
    with pytest.raises(ValueError, match="task"):
        tasks.task_onboard_config("sawing")
