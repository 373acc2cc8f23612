"""Plant construction hooks."""

from __future__ import annotations

import numpy as np


def test_scene_hook_adds_objects_without_moving_robot_ids():
    """``Plant(scene=...)`` adds world geoms; the robot's bodies, actuators and dynamics are
    unchanged (world geoms are numbered first, so geom ids shift: the plant looks names up)."""
    import mujoco

    from rdm.plant import Plant

    def scene(spec):
        spec.worldbody.add_geom(
            name="task_board",
            type=mujoco.mjtGeom.mjGEOM_BOX,
            size=[0.1, 0.1, 0.01],
            pos=[2, 2, 0.5],
        )

    a, b = Plant("rdm", seed=1), Plant("rdm", seed=1, scene=scene)
    assert b.model.ngeom == a.model.ngeom + 1
    assert mujoco.mj_name2id(b.model, mujoco.mjtObj.mjOBJ_GEOM, "task_board") >= 0
    assert a.model.nbody == b.model.nbody and a.model.nu == b.model.nu
    for p in (a, b):
        p.set_rotor_thrusts([9.0, 9.0, 9.0, 9.0])
        p.step(50)
    np.testing.assert_array_equal(a.data.qpos, b.data.qpos)
