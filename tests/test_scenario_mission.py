"""The operator's mission through every wire (MuJoCo plant, Neuron mirrors on CAN, the Spinal
mirror over rosserial, the onboard node): take off, go to a point, land (the quick form) with
each injected flight fault; the whole mission (fold, perch, arm motion, unperch, unfold, land);
a foot-sensor loss while perched. Every run must end safe (disarmed on the floor or held
perched, tilt in flight at most 30 deg, no duty above motor_info's maximum) and the node (or
Spinal) must have noticed the fault."""

from __future__ import annotations

import numpy as np
import pytest

from rdm.scenarios import perching
from rdm.scenarios.common import roll_pitch, truth_arrays
from rdm.scenarios.mission import (
    ARM_AT,
    BEYOND_AIRFRAME,
    DEFAULT_DURATION,
    FAULTS,
    GOTO_OFFSET,
    MAX_TILT_DEG,
    PERCHED_ARM,
    PERCHED_FAULTS,
    QUICK_DURATION,
    SETTLE_S,
    run,
)

pytestmark = [pytest.mark.slow, pytest.mark.timeout(600)]
#: The faults that must end safe (every one: ``BEYOND_AIRFRAME`` is empty).
SURVIVABLE = [f for f in FAULTS if f not in BEYOND_AIRFRAME]


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    base = tmp_path_factory.mktemp("mission")
    out = {}
    for fault in SURVIVABLE:
        if fault in PERCHED_FAULTS:  # the whole mission up to the perch; it ends held there
            result = run(base, duration=DEFAULT_DURATION, fault=fault)
        else:
            result = run(base, duration=QUICK_DURATION, fault=fault, quick=True)
        out[fault] = (result.facts["mission"], truth_arrays(result.stack), result)
    return out


@pytest.fixture(scope="module")
def whole(tmp_path_factory):
    result = run(tmp_path_factory.mktemp("whole"), duration=DEFAULT_DURATION)
    return result.facts["mission"], truth_arrays(result.stack), result


@pytest.mark.parametrize("fault", SURVIVABLE)
def test_every_fault_ends_safe_and_is_detected(runs, fault) -> None:
    record, a, result = runs[fault]
    perched = fault in PERCHED_FAULTS
    assert record["outcome"] == ("perched" if perched else "landed"), record
    assert record["safe"] is True
    assert record["final_state"] == ("armed" if perched else "idle")
    if fault != "none":
        assert record["fault_detected"] is True, record
    # no false trip of the lost-rotor detection (it cuts the motors): only the faults that
    # stop a rotor (a dead ESC, the ESC of a resetting Neuron) trip it
    if fault not in ("dead-esc", "neuron-reset"):
        assert "rotor_lost" not in record["monitors"], record
    # independent of the record: the truth log's own tilt and heights
    floor = a["cog"][np.searchsorted(a["t"], ARM_AT) - 1, 2]
    flying = a["cog"][:, 2] > floor + 0.05
    tilt = np.degrees(np.abs(roll_pitch(a["quat"][flying]))).max()
    assert tilt <= MAX_TILT_DEG
    assert a["cog"][:, 2].max() > floor + 0.8  # it did take off (1 m)
    if perched:  # held on the ceiling: the foot in contact to the end
        assert a["contact"][-200:].all()
    else:
        assert abs(a["cog"][-1, 2] - floor) < 0.05
    assert record["max_duty"] <= result.stack.onboard.config.pwm_info.max_pwm


def test_the_whole_mission_perches_moves_the_arm_and_lands(whole) -> None:
    record, a, result = whole
    assert (record["outcome"], record["safe"], record["final_state"]) == ("landed", True, "idle")
    said = [text.split(" ->") for _, text in record["operator"]]
    assert [c for c, _ in said] == [
        "takeoff", "goto", "joints fold", "perch", "joints arm", "joints arm back",
        "unperch", "joints unfold", "land",
    ]  # fmt: skip
    assert all(r == " None" for _, r in said), said  # every command accepted
    times = {c: t for t, text in record["operator"] for c in [text.split(" ->")[0]]}
    t = a["t"]
    # the ground truth: in contact from the end of the contact transient (the settling time
    # after the node saw the contact) until the unperch
    flight = result.stack.onboard.flight
    assert flight.counts["contact"] == 1
    assert a["contact"][t < flight.perched_at].sum() < 0.1 / (t[1] - t[0])  # a touch at most
    held = (t > flight.perched_at + SETTLE_S) & (t < times["unperch"])
    assert held.sum() > 400 and a["contact"][held].all()
    assert not a["contact"][(t > times["unperch"] + 2.0) & (t < times["land"])].any()
    # the arm reached its goal while perched (the truth's joint angles)
    at_goal = np.searchsorted(t, times["joints arm back"]) - 1
    np.testing.assert_allclose(a["q"][at_goal, :6], PERCHED_ARM, atol=0.05)
    # and the posture it perched in
    at_perch = np.searchsorted(t, times["joints arm"]) - 1
    np.testing.assert_allclose(a["q"][at_perch, :6], perching.PERCH_POSTURE, atol=0.05)
    floor = a["cog"][np.searchsorted(t, ARM_AT) - 1, 2]
    flying = a["cog"][:, 2] > floor + 0.05
    assert np.degrees(np.abs(roll_pitch(a["quat"][flying]))).max() <= MAX_TILT_DEG
    assert abs(a["cog"][-1, 2] - floor) < 0.05


def test_the_mission_flies_where_it_is_told(runs) -> None:
    record, a, _ = runs["none"]
    start = a["cog"][np.searchsorted(a["t"], ARM_AT)]
    top = a["cog"][np.argmax(a["cog"][:, 2])]
    # take-off 1 m, then 0.5 m in x and 5 cm down (the goto), within the hover tolerance
    assert top[2] - start[2] == pytest.approx(1.0, abs=0.1)
    goal = a["cog"][np.searchsorted(a["t"], record["operator"][2][0]) - 1]  # at the land
    assert goal[0] - start[0] == pytest.approx(GOTO_OFFSET[0], abs=0.15)
    assert goal[2] - start[2] == pytest.approx(1.0 + GOTO_OFFSET[2], abs=0.1)
    assert [text.split(" ->")[0] for _, text in record["operator"]] == ["takeoff", "goto", "land"]


def test_mocap_loss_lands_by_spinals_own_force_landing(runs) -> None:
    _, _, result = runs["mocap-loss"]
    # the node went silent, so Spinal's 500 ms command timeout started its force landing
    assert result.facts["spinal_failsafes"] == {"failsafe_timeout": 1}
    assert result.stack.onboard.flight.counts["touchdown_imu"] == 1


def test_uart_cut_of_300_ms_is_ridden_out(runs) -> None:
    record, _, result = runs["uart-cut"]
    assert record["monitors"]["spinal_silent"] == 1
    assert not result.facts["spinal_failsafes"]  # shorter than Spinal's command timeout


def test_bad_adc_scale_is_refused_by_spinal(runs) -> None:
    _, _, result = runs["bad-adc-scale"]
    assert result.facts["spinal_rejected"] == {"adc_scale_implausible": 1}
    assert result.stack.spinal.adc_scale == 1.0
