"""The plant's collision gate (rdm.plant.contact_gate): MuJoCo's collision detection is skipped
only in steps that provably have no contact, and nothing simulated changes.

Oracles: MuJoCo's own geometry (``mj_geomDistance`` between every robot geom and the ceiling
and floor, ``mj_kinematics`` of the stepped state), and twin plants / stacks built with
``contact_gate=False`` (MuJoCo collides in every step): bit-equal states and byte-equal logs.
"""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
import pytest
from hover_run_files import hover_run

from rdm._rdm import ContactGateCore
from rdm.plant import Plant
from rdm.plant.contact_gate import GATE_SLACK, build_contact_gate, gate_refusal
from rdm.plant.mjcf import CEILING_GEOM, FLOOR_GEOM

BIT = int(mujoco.mjtDisableBit.mjDSBL_CONTACT)


def _plant(gate: bool = True, **kw) -> Plant:
    return Plant("rdm", seed=0, ceiling_height=2.0, floor_height=0.0, contact_gate=gate, **kw)


def _robot_geoms(m: mujoco.MjModel) -> list[int]:
    return [g for g in range(m.ngeom) if m.body_weldid[m.geom_bodyid[g]] != 0]


def _mujoco_gap(m: mujoco.MjModel, d: mujoco.MjData) -> float:
    """Smallest distance between a robot geom and the ceiling or the floor, by MuJoCo."""
    env = [m.geom(CEILING_GEOM).id, m.geom(FLOOR_GEOM).id]
    fromto = np.zeros(6)

    def collide(a: int, b: int) -> bool:
        return bool(m.geom_contype[a] & m.geom_conaffinity[b])

    return min(
        mujoco.mj_geomDistance(m, d, g, e, 10.0, fromto)
        for g in _robot_geoms(m)
        for e in env
        if collide(g, e) or collide(e, g)
    )


def _random_state(plant: Plant, rng: np.random.Generator, speed: float) -> None:
    """A random pose between floor and ceiling, joints inside their ranges, random speeds."""
    m, d = plant.model, plant.data
    d.qpos[0:3] = (rng.uniform(-0.5, 0.5), rng.uniform(-0.5, 0.5), rng.uniform(0.05, 1.95))
    quat = rng.normal(size=4)
    d.qpos[3:7] = quat / np.linalg.norm(quat)
    for j in range(1, m.njnt):
        lo, hi = m.jnt_range[j] if m.jnt_limited[j] else (-np.pi, np.pi)
        d.qpos[m.jnt_qposadr[j]] = rng.uniform(lo, hi)
    d.qvel[:] = rng.uniform(-speed, speed, size=m.nv)
    mujoco.mj_forward(m, d)


def test_clearance_never_exceeds_mujocos_distance() -> None:
    plant = _plant()
    gate = plant.contact_gate
    assert gate is not None
    m = plant.model
    rbound = max(m.geom_rbound[g] for g in _robot_geoms(m))
    rng = np.random.default_rng(1)
    near = 0
    for _ in range(300):
        _random_state(plant, rng, 0.0)
        clearance, _ = gate.read()
        gap = _mujoco_gap(m, plant._data)
        # a lower bound of the distance (spheres contain the geoms), not a vacuous one; a
        # geom in the surface (MuJoCo: minus its depth) has its sphere in it too
        assert clearance <= max(gap, 0.0) + 1e-9
        assert clearance >= gap - 2 * rbound
        near += gap < 0.05
    assert near > 5  # the sample reaches the surfaces too


def test_reach_bounds_the_motion_of_one_step() -> None:
    """After ``mj_step`` the views hold the old poses and the new velocities (what the gate
    reads); the new poses' geoms moved no further than the reach without its slack."""
    plant = _plant()
    gate = plant.contact_gate
    m, d = plant.model, plant._data
    robot = _robot_geoms(m)
    rng = np.random.default_rng(2)
    ratios = []
    for _ in range(200):
        _random_state(plant, rng, 8.0)
        mujoco.mj_step(m, d)
        before = d.geom_xpos[robot].copy()
        _, reach = gate.read()
        mujoco.mj_kinematics(m, d)
        moved = float(np.max(np.linalg.norm(d.geom_xpos[robot] - before, axis=1)))
        bound = reach - GATE_SLACK
        assert moved <= bound * 1.02 + 1e-9  # first order; the slack covers the rest
        ratios.append(moved / bound)
    assert max(ratios) > 0.1  # the bound is not loose by an order of magnitude


@pytest.mark.parametrize("case", ["floor", "ceiling"])
def test_landing_and_hitting_the_ceiling_are_bit_identical(case: str) -> None:
    runs = []
    for gate in (True, False):
        plant = _plant(gate)
        if case == "floor":
            plant.reset(base_position=(0.0, 0.0, 0.5))  # falls, rotors off
        else:
            plant.reset(base_position=(0.0, 0.0, 1.75))
            plant.data.qvel[2] = 3.0  # thrown up at the ceiling
        trace, contacts = [], 0
        for _ in range(700):
            plant.step(1)
            d = plant._data
            trace.append(d.qpos.tobytes() + d.qvel.tobytes())
            contacts += d.ncon > 0
        runs.append((trace, contacts, plant.contact_gate))
    (with_gate, contacts, gate), (without, contacts_plain, none) = runs
    assert none is None and gate is not None
    assert contacts > 20 and contacts == contacts_plain
    assert gate.off_steps > 50 and gate.on_steps > 50  # it switched, both ways
    for k, (a, b) in enumerate(zip(with_gate, without, strict=True)):
        assert a == b, f"step {k}"


def _flying(steps: int) -> tuple[Plant, ContactGateCore]:
    """A plant dropped at 1 m, ``steps`` steps later (contacts off), and its gate."""
    plant = _plant()
    gate = plant.contact_gate
    assert gate is not None
    plant.reset(base_position=(0.0, 0.0, 1.0))
    plant.step(steps)
    assert gate.off and plant.model.opt.disableflags & BIT
    return plant, gate


def test_outside_changes_and_reset_turn_contacts_on() -> None:
    plant, gate = _flying(3)
    d = plant.data  # the caller may move the robot into the floor: collide in full
    assert not gate.off
    assert not plant.model.opt.disableflags & BIT
    d.qpos[2] = 0.0
    plant.step(1)
    assert plant._data.ncon > 0 and not gate.off
    plant.reset(base_position=(0.0, 0.0, 1.0))
    assert not gate.off


def test_a_nan_state_keeps_contacts_on() -> None:
    plant, gate = _flying(2)
    plant._data.qvel[0] = np.nan
    assert gate.update() is False and not gate.off
    plant._data.qvel[0] = 0.0
    plant._data.geom_xpos[-1, 2] = np.nan
    assert gate.update() is False and not gate.off


def test_where_the_gate_does_not_apply() -> None:
    assert Plant("rdm", fixed_base=True).contact_gate is None
    assert Plant("rdm", scene=lambda spec: None).contact_gate is None
    assert _plant(False).contact_gate is None

    def model(body: str, world: str = "") -> mujoco.MjModel:
        return mujoco.MjModel.from_xml_string(
            f"<mujoco><worldbody>{world}"
            '<geom name="floor" type="plane" size="1 1 .1" contype="0" conaffinity="1"/>'
            f"{body}</worldbody></mujoco>"
        )

    robot = (
        '<body name="r"><freejoint/>'
        '<geom type="capsule" size=".05 .2" contype="1" conaffinity="0"/></body>'
    )
    assert gate_refusal(model(robot), 1) is None
    ball = robot.replace("</body>", '<body><joint type="ball"/><geom size=".05"/></body></body>')
    assert gate_refusal(model(ball), 1) == "a ball joint in the robot"
    other = '<body><freejoint/><geom size=".1" contype="0" conaffinity="1"/></body>'
    assert gate_refusal(model(robot + other), 1) == "two moving geoms can collide"
    sphere = '<geom type="sphere" size=".1" pos="0 0 2" contype="0" conaffinity="1"/>'
    assert gate_refusal(model(robot, sphere), 1) == "an obstacle that is neither a plane nor a box"
    m = model(robot)
    m.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONTACT)
    assert gate_refusal(m, 1) == "contacts already disabled"
    assert build_contact_gate(m, mujoco.MjData(m), 1) is None


def test_bad_arguments_are_refused() -> None:
    m = mujoco.MjModel.from_xml_string("<mujoco><worldbody/></mujoco>")
    d = mujoco.MjData(m)
    views = (d.geom_xpos, d.xpos, d.xanchor, d.qvel)
    with pytest.raises(ValueError, match="dt"):
        ContactGateCore(0.0, 0.01, [], [], [], 0, [], [], 0, m.opt, BIT, *views)
    with pytest.raises(ValueError, match="margins"):
        plane = ([0.0, 0.0, 0.0], [0.0, 0.0, 1.0])
        ContactGateCore(0.001, 0.01, [plane], [], [(0, 0.1, [])], 0, [], [], 0, m.opt, BIT, *views)
    gate = ContactGateCore(0.001, 0.01, [], [], [(3, 0.1, [])], 0, [], [], 0, m.opt, BIT, *views)
    with pytest.raises(ValueError, match="geom_xpos"):
        gate.update()
    assert not gate.off


def _state(stack) -> tuple[bytes, tuple[int, int] | None]:
    assert stack.loop.kernel is not None
    d = stack.plant._data
    g = stack.plant.contact_gate
    counts = None if g is None else (g.off_steps, g.on_steps)
    return d.qpos.tobytes() + d.qvel.tobytes() + d.ctrl.tobytes(), counts


def _run_hover(tmp: Path, gate: bool) -> tuple[dict[str, bytes], bytes, tuple[int, int] | None]:
    # the boot on the floor, the take-off, 1 s of flight
    files, (state, counts) = hover_run(tmp, "g", 3.5, _state, plant_contact_gate=gate)
    return files, state, counts


def test_the_lockstep_stack_writes_the_same_bytes_with_and_without_the_gate(
    tmp_path: Path,
) -> None:
    files, state, counts = _run_hover(tmp_path / "gate", True)
    files_plain, state_plain, none = _run_hover(tmp_path / "plain", False)
    assert none is None and counts is not None
    assert counts[0] > 800  # the kernel's steps skipped collisions in flight
    assert sorted(files) == sorted(files_plain)
    for name in files:
        assert files[name] == files_plain[name], name
    assert state == state_plain
