"""MuJoCo's sensors computed only in the forward pass a reading runs (``Plant(lazy_sensors)``,
docs/plant.md "Lazy sensors"), and the address probe the kernel writes the flag through.

Oracles: twin plants and stacks built with ``lazy_sensors=False`` (MuJoCo computes the
sensors in every step): bit-equal states and readings, byte-equal logs; the bindings'
``opt.disableflags`` property for the probed address.
"""

from __future__ import annotations

import ctypes
from pathlib import Path

import mujoco
import numpy as np
import pytest
from hover_run_files import hover_run

import rdm.plant.plant as plant_module
from rdm.plant import Plant
from rdm.plant.option_flags import disableflags_address

SENSOR = int(mujoco.mjtDisableBit.mjDSBL_SENSOR)


def _plant(lazy: bool) -> Plant:
    return Plant("rdm", seed=3, ceiling_height=2.0, floor_height=0.0, lazy_sensors=lazy)


def _readings(plant: Plant) -> bytes:
    imu = plant.imu()
    wrench = plant.wrench("foot_wrench")
    values = [imu.gyro, imu.accel, imu.mag, wrench.force, wrench.torque]
    return b"".join(np.asarray(v, dtype=float).tobytes() for v in values)


def _drop_sleep_and_wake(lazy: bool, every: int) -> tuple[list[bytes], Plant]:
    """Dropped onto the floor with the rotors stopped (it lands and falls asleep), then the
    rotors spin up (the command wakes it): readings every ``every`` steps, states every
    step. Whether a sleeping robot's frozen sensor values match depends on which step last
    computed them, hence several reading periods."""
    plant = _plant(lazy)
    plant.reset(base_position=(0.0, 0.0, 0.3))
    trace = []
    for step in range(2500):
        if step == 1800:
            plant.set_rotor_thrusts(np.full(len(plant.rotor_names), 2.0))
        plant.step(1)
        d = plant._data
        trace.append(d.qpos.tobytes() + d.qvel.tobytes())
        if step % every == every - 1:
            trace.append(_readings(plant))
    return trace, plant


@pytest.mark.parametrize("every", [1, 2, 5, 7])
def test_readings_and_states_are_bit_identical_through_sleep_and_wake(every: int) -> None:
    lazy, plant = _drop_sleep_and_wake(True, every)
    plain, plain_plant = _drop_sleep_and_wake(False, every)
    assert plant._sensor_bit == SENSOR and plain_plant._sensor_bit == 0
    sleep = plant.sleep
    assert sleep is not None and sleep.wakes >= 1  # it slept, and the rotors woke it
    for k, (a, b) in enumerate(zip(lazy, plain, strict=True)):
        assert a == b, f"record {k}"


def test_the_flags_are_the_models_own_between_steps() -> None:
    plant = _plant(True)
    plant.reset(base_position=(0.0, 0.0, 1.0))
    plant.step(5)
    assert not plant.model.opt.disableflags & SENSOR  # (the collision gate owns its own bit)
    # a user's own forward pass computes the sensors (the bit is not left set)
    d = plant.data
    d.sensordata[:] = np.nan
    mujoco.mj_forward(plant.model, d)
    assert np.isfinite(d.sensordata).all()


def test_a_failing_step_restores_the_flags() -> None:
    plant = _plant(True)
    plant.reset(base_position=(0.0, 0.0, 1.0))
    flags = plant.model.opt.disableflags

    def fail() -> None:
        raise RuntimeError("boom")

    plant._state.rotors_in_core = False  # the rotors through the face's callback, which fails
    plant._step_rotors = fail  # type: ignore[method-assign]
    with pytest.raises(RuntimeError, match="boom"):
        plant.step(1)
    assert plant.model.opt.disableflags == flags  # the first step: the gate has not run


def _scene_flags(disable: int = 0, enable: int = 0):
    def edit(spec: mujoco.MjSpec) -> None:
        spec.option.disableflags |= disable
        spec.option.enableflags |= enable

    return edit


def test_sensors_stay_in_every_step_where_lazy_ones_could_differ() -> None:
    # the model disables its sensors itself: the plant leaves the bit alone
    off = Plant("rdm", seed=0, scene=_scene_flags(disable=SENSOR), lazy_sensors=True)
    assert off._sensor_bit == 0 and off._flags_address is None
    off.step(3)
    assert off.model.opt.disableflags & SENSOR
    # sleeping the plant does not watch (a scene's model enabling it): sensors every step
    sleep_bit = int(mujoco.mjtEnableBit.mjENBL_SLEEP)
    unwatched = Plant("rdm", seed=0, scene=_scene_flags(enable=sleep_bit), lazy_sensors=True)
    assert unwatched.sleep is None and unwatched._sensor_bit == 0
    # a plain scene: nothing sleeps, the bit is used
    assert Plant("rdm", seed=0, scene=_scene_flags(), lazy_sensors=True)._sensor_bit == SENSOR


def test_the_probe_finds_the_field_in_both_directions() -> None:
    plant = _plant(True)
    m = plant.model
    address = disableflags_address(m)
    assert address is not None
    cell = ctypes.c_int32.from_address(address)
    before = m.opt.disableflags
    m.opt.disableflags = before | SENSOR
    assert cell.value == before | SENSOR
    cell.value = before
    assert m.opt.disableflags == before
    assert plant._flags_address == address


def test_the_probe_declines_what_it_cannot_check() -> None:
    class NoAddress:
        opt = None

    assert disableflags_address(NoAddress()) is None  # type: ignore[arg-type]
    plain = _plant(False)
    assert plain._flags_address is None  # no bit to write: the kernel keeps the property


def _state(stack) -> tuple[bytes, int]:
    assert stack.loop.kernel is not None
    d = stack.plant._data
    state = d.qpos.tobytes() + d.qvel.tobytes() + d.ctrl.tobytes()
    # sensordata is the present state's after the forward pass a reading runs
    state += stack.plant.data.sensordata.tobytes()
    return state, stack.plant._sensor_bit


def _run_hover(tmp: Path, lazy: bool) -> tuple[dict[str, bytes], bytes, int]:
    # the boot on the floor (asleep), the take-off, 1 s of flight
    files, (state, bit) = hover_run(tmp, "s", 3.5, _state, plant_lazy_sensors=lazy)
    return files, state, bit


def test_the_lockstep_stack_writes_the_same_bytes_with_and_without_lazy_sensors(
    tmp_path: Path,
) -> None:
    files, state, bit = _run_hover(tmp_path / "lazy", True)
    files_plain, state_plain, bit_plain = _run_hover(tmp_path / "plain", False)
    assert bit == SENSOR and bit_plain == 0
    assert sorted(files) == sorted(files_plain)
    for name in files:
        assert files[name] == files_plain[name], name
    assert state == state_plain


def test_an_address_outside_the_model_is_not_written(tmp_path: Path, monkeypatch) -> None:
    # the kernel writes the flag through Plant._flags_address only inside the model it
    # holds; anything else (here a bogus address) falls back to opt.disableflags
    files, state, _ = _run_hover(tmp_path / "probed", True)
    monkeypatch.setattr(plant_module, "disableflags_address", lambda model: 8)
    files_bogus, state_bogus, bit = _run_hover(tmp_path / "bogus", True)
    assert bit == SENSOR
    assert sorted(files) == sorted(files_bogus)
    for name in files:
        assert files[name] == files_bogus[name], name
    assert state == state_bogus
