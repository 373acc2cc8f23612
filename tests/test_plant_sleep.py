"""The robot at rest sleeps in MuJoCo and its own commands wake it (rdm.plant.sleep).

Oracles: a twin plant built with ``sleep=False`` (MuJoCo never lets the robot sleep), which
settles on where the sleeping one froze; and, for the step a command wakes the robot, a
never-sleeping plant given the sleeping one's exact state: the woken robot must be integrated
with the new controls in that very step, not one step later.
"""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

import rdm.plant.sleep as sleep_module
from rdm.plant import EscParams, Plant, ServoParams
from rdm.plant.sleep import SLEEP_AVAILABLE

pytestmark = pytest.mark.skipif(not SLEEP_AVAILABLE, reason="this MuJoCo has no sleeping")

HOVER = (14.0, 14.0, 3.8, 3.8)  # about the hover thrusts, N


def _resting(sleep: bool) -> Plant:
    """The robot dropped on the floor as the stack starts it (its servo and ESC models),
    0.6 s later."""
    plant = Plant(
        "rdm",
        seed=0,
        ceiling_height=None,
        floor_height=0.0,
        servo=ServoParams(kp=150.0, kv=5.0),
        esc=EscParams(tau=0.01),
        sleep=sleep,
    )
    plant.reset(base_position=(0.0, 0.0, 0.12))
    plant.step(600)
    return plant


def _asleep(plant: Plant) -> bool:
    return plant.sleep is not None and plant.sleep.asleep()


def test_the_resting_robot_sleeps_and_is_frozen() -> None:
    plant, twin = _resting(True), _resting(False)
    assert _asleep(plant) and twin.sleep is None
    q = plant._data.qpos.copy()
    plant.step(100)
    twin_q = twin._data.qpos.copy()
    twin.step(100)
    assert np.array_equal(plant._data.qpos, q) and not plant._data.qvel.any()
    assert np.max(np.abs(twin._data.qpos - twin_q)) < 1e-6  # the twin only settles
    assert np.max(np.abs(plant._data.qpos - twin._data.qpos)) < 1e-4  # froze where it stood


def _awake_copy(plant: Plant) -> Plant:
    """A never-sleeping plant in the sleeping one's exact physics state."""
    copy = _resting(False)
    kind = mujoco.mjtState.mjSTATE_INTEGRATION
    state = np.empty(mujoco.mj_stateSize(plant.model, kind))
    mujoco.mj_getState(plant.model, plant._data, state, kind)
    mujoco.mj_setState(copy.model, copy._data, state, kind)
    copy._state.stale = copy._state.needs_step1 = True
    return copy


def test_rotor_command_wakes_it_in_the_same_step() -> None:
    plant, twin = _resting(True), _resting(False)
    same_state = _awake_copy(plant)
    for p in (plant, twin, same_state):
        p.set_rotor_thrusts([2.0 * t for t in HOVER])  # lifts off through the ESC lag
        p.step(1)
    assert not _asleep(plant) and plant.sleep is not None and plant.sleep.wakes == 1
    # this step's acceleration is the awake robot's: the new thrust acted in this very step
    np.testing.assert_allclose(plant._data.qacc, same_state._data.qacc, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(plant._data.qpos, same_state._data.qpos, rtol=0, atol=1e-12)
    plant.step(300)
    twin.step(300)
    assert plant.ground_truth().base_position[2] > 0.12  # lifted off (it rested at 0.07)
    np.testing.assert_allclose(
        plant.ground_truth().base_position, twin.ground_truth().base_position, atol=1e-3
    )
    assert plant.sleep.wakes == 1 and not _asleep(plant)  # in flight the controls change


def test_a_servo_goal_wakes_it() -> None:
    plant, twin = _resting(True), _resting(False)
    q = np.zeros(len(plant.joint_names))
    q[5] = 0.3  # q6, the end-effector roll
    for p in (plant, twin):
        p.set_servo_targets(q)
        p.step(200)
    assert plant.sleep is not None and plant.sleep.wakes == 1
    np.testing.assert_allclose(plant.servo_positions(), twin.servo_positions(), atol=1e-3)
    assert abs(plant.servo_positions()[5] - 0.3) < 0.01


def test_a_push_wakes_it() -> None:
    plant, twin = _resting(True), _resting(False)
    for p in (plant, twin):
        p.apply_body_wrench("end_effector", force=(0.0, 0.0, 40.0))
        p.step(50)
    assert not _asleep(plant)
    np.testing.assert_allclose(plant._data.qpos, twin._data.qpos, atol=1e-3)
    assert plant._data.qvel.any()


def test_an_outside_change_of_the_state_wakes_it() -> None:
    plant = _resting(True)
    plant.data.qpos[2] += 0.05  # lifted by hand: it must fall
    plant.step(1)
    assert not _asleep(plant)
    plant.step(50)
    assert plant._data.qvel[2] < -0.1


def test_it_falls_asleep_again_only_after_a_quiet_spell() -> None:
    plant = _resting(True)
    q = np.zeros(len(plant.joint_names))
    q[5] = 0.3
    plant.set_servo_targets(q)
    plant.step(1)
    assert not _asleep(plant)
    for _ in range(30):  # the same goal held: the robot settles (it rocks on its round
        plant.step(100)  # links first), then sleeps again
        if _asleep(plant):
            break
    assert _asleep(plant) and plant.sleep is not None and plant.sleep.wakes == 1


def test_reset_starts_awake_and_sleep_false_never_sleeps() -> None:
    plant = _resting(True)
    plant.reset(base_position=(0.0, 0.0, 0.12))
    assert not _asleep(plant)
    never = _resting(False)
    assert never.sleep is None
    assert never.model.opt.enableflags & int(mujoco.mjtEnableBit.mjENBL_SLEEP) == 0
    assert never._data.qvel.any()  # still settling by ~1e-10: MuJoCo never froze it


def test_a_plant_with_a_scene_does_not_sleep() -> None:
    """The tasks move their static objects through ``model.body_pos``, which a sleeping-enabled
    MuJoCo would not pick up (it computes static poses once): such a plant stays awake."""

    def scene(spec: mujoco.MjSpec) -> None:
        spec.worldbody.add_body(name="board", pos=[0.5, 0.0, 0.3]).add_geom(size=[0.1, 0.1, 0.01])

    plant = Plant("rdm", ceiling_height=None, floor_height=0.0, scene=scene)
    assert plant.sleep is None
    assert plant.model.opt.enableflags & int(mujoco.mjtEnableBit.mjENBL_SLEEP) == 0
    plant.reset(base_position=(0.0, 0.0, 0.12))
    plant.step(600)
    assert plant._data.ntree_awake == plant.model.ntree


def _wake_and_rest(sleep_module_bit: int, monkeypatch: pytest.MonkeyPatch) -> tuple[list, int]:
    """Resting, a 0.2 s servo goal ramp ("never" in every step: it wakes), then the goal held
    until MuJoCo counts down to sleep, and a ramp back started inside that countdown (the
    step that resets it matters), then rest until it sleeps: states and sleep counters every
    step, and how often MuJoCo's sleeping was switched."""
    monkeypatch.setattr(sleep_module, "_SLEEP_ENABLE", sleep_module_bit)
    plant = _resting(True)
    d, trace, switches, on = plant._data, [], 0, None
    tree = plant.sleep.trees[0] if plant.sleep is not None else 0
    q = np.zeros(len(plant.joint_names))
    second = None  # the step the ramp back starts
    for step in range(7000):
        counting = -(1 + mujoco.mjMINAWAKE) < d.tree_asleep[tree] < 0
        if second is None and step > 210 and counting:
            second = step
        if 10 <= step < 210 or (second is not None and second <= step < second + 200):
            q[5] += 0.0015 if second is None else -0.0015
            plant.set_servo_targets(q)
        plant.step(1)
        trace.append(d.qpos.tobytes() + d.qvel.tobytes() + d.tree_asleep.tobytes())
        now_on = bool(plant.model.opt.enableflags & int(mujoco.mjtEnableBit.mjENBL_SLEEP))
        switches += on is not None and now_on != on
        on = now_on
    assert second is not None and _asleep(plant)  # the countdown was cut, then it slept
    return trace, switches


def test_mujocos_sleeping_off_while_the_robot_cannot_sleep_changes_nothing(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # reference: the flag never switched (a zero bit); then the rule as shipped
    plain, none = _wake_and_rest(0, monkeypatch)
    switched, switches = _wake_and_rest(int(mujoco.mjtEnableBit.mjENBL_SLEEP), monkeypatch)
    assert none == 0 and switches >= 4  # off and on again, twice
    for k, (a, b) in enumerate(zip(plain, switched, strict=True)):
        assert a == b, f"step {k}"
