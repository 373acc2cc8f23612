"""Simulated objects of the perching manipulation tasks (paper Sec. VII-D, Fig. 14) and the
tools on the end effector, added to a built :class:`rdm.plant.Plant`'s MuJoCo scene.

The plant has no hook to edit its ``MjSpec`` before it compiles, so :func:`add_task_objects`
edits ``plant.spec`` after construction, recompiles in place and swaps ``model``/``data``
(and the foot-contact tracker, which holds the model). Everything added comes *after* the
robot in MuJoCo's id order (new world bodies after the robot tree, new geoms on the massless
``end_effector`` body, a valve hinge after every robot joint, no new actuators or sensors),
so every id and address the plant and its nodes cached stays valid; the function checks this
and raises otherwise. Call it before the first ``plant.step`` (it resets the plant).

Tools (ASSUMPTION: the paper swaps tools between experiments; here all three are mounted
coaxially along the end-effector x axis and collision bits make each touch only its own
object, so one perch can run every task):

* drill bit: capsule 0..``DRILL_LEN`` m, radius 5 mm (point contact at its tip);
* brush: a sphere of radius ``BRUSH_RADIUS`` centred ``BRUSH_AT`` m out (sliding contact);
* gripper: two finger capsules at y = +-``FINGER_Y`` that straddle the valve's handle bar.

Objects (positions relative to the nominal perch spot of the foot, see :class:`TaskLayout`):
a horizontal wood board below the arm (drilling), a horizontal panel (painting; the paper
paints a wall, see docs/scenarios.md for why the hanging arm cannot), and a
valve: a hand-wheel on a vertical hinge with damping and dry friction (opening resistance).
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from rdm.plant import Plant
from rdm.plant.mjcf import CEILING_GEOM, FLOOR_GEOM, ROBOT_GROUP
from rdm.plant.truth import FootContactTracker

#: Collision bits: robot links keep ROBOT_GROUP (1) and touch every object; each tool
#: touches only the object with its bit.
DRILL_BIT, BRUSH_BIT, GRIPPER_BIT = 2, 4, 8
DRILL_LEN = 0.10  # m, bit length from the tool flange
DRILL_RADIUS = 0.005
BRUSH_AT = 0.08  # m
BRUSH_RADIUS = 0.02
FINGER_Y = 0.02  # m, finger axis offset from the tool axis
FINGER_RADIUS = 0.005
FINGER_SPAN = (0.04, 0.09)  # m along the tool axis
GRIPPER_AT = 0.07  # m: where the handle bar sits between the fingers (tool axis)

BOARD = "task_board"
PANEL = "task_panel"
VALVE = "task_valve"
VALVE_JOINT = "task_valve_hinge"
DRILL_GEOM = "tool_drill"
BRUSH_GEOM = "tool_brush"
FINGER_GEOMS = ("tool_finger_l", "tool_finger_r")
HANDLE_GEOM = "task_valve_handle"


@dataclass(frozen=True)
class TaskLayout:
    """Where the objects are, relative to the nominal foot position on the ceiling.

    ASSUMPTIONS (the paper shows photos only): ``nominal_foot`` is where the perching
    scenario's foot lands (seed 0); the board, panel and valve are placed inside
    the hanging arm's reach in the x-z plane of the arm. Stiffness/friction: wood-like stiff
    contacts (2 ms time constant), board/valve friction 0.6, painted panel 0.3 (a wet brush
    slides), valve damping 0.3 N m s/rad and dry friction 0.15 N m.
    """

    nominal_foot: tuple[float, float, float] = (0.523, 0.020, 1.600)
    board_top_z: float = 0.50  # m, world
    board_x: tuple[float, float] = (0.26, 0.46)  # relative to the foot x
    board_half_y: float = 0.15
    panel_top_z: float = 0.60  # m, world: the painted panel (horizontal, facing up)
    panel_x: tuple[float, float] = (0.02, 0.72)  # relative to the foot x
    panel_half_y: float = 0.15
    valve_x: float = 0.19  # relative to the foot x
    valve_handle_z: float = 0.48  # m, world, handle bar centre
    valve_damping: float = 0.3  # N m s/rad
    valve_friction: float = 0.15  # N m (dry friction of the stem)
    board_friction: float = 0.6
    panel_friction: float = 0.3
    contact_solref: tuple[float, float] = (0.002, 1.0)

    def board_point(self, dx: float, dy: float) -> np.ndarray:
        """World point on the board's top face at (foot x + dx, foot y + dy)."""
        fx, fy, _ = self.nominal_foot
        return np.array([fx + dx, fy + dy, self.board_top_z])

    @property
    def valve_axis(self) -> np.ndarray:
        """World point of the valve hinge axis at the handle bar's height (axis = +z)."""
        fx, fy, _ = self.nominal_foot
        return np.array([fx + self.valve_x, fy, self.valve_handle_z])


def _object_geom(body: mujoco.MjsBody, bits: int, friction: float, solref, **kw) -> None:
    g = body.add_geom(**kw)
    g.contype = 0
    g.conaffinity = 0  # off until enable_objects(): the robot flies up through this space
    g.userdata = [float(ROBOT_GROUP | bits)]
    g.condim = 3
    g.priority = 2  # the object's friction and stiffness win over the robot geoms'
    g.friction = [friction, 0.005, 1e-4]
    g.solref = list(solref)
    g.density = 0.0


def _tool_geom(body: mujoco.MjsBody, bit: int, **kw) -> None:
    g = body.add_geom(**kw)
    g.contype = bit
    g.conaffinity = 0
    g.condim = 3
    g.density = 0.0
    g.rgba = [0.8, 0.5, 0.1, 1.0]


def edit_spec(spec: mujoco.MjSpec, layout: TaskLayout, tasks: tuple[str, ...], ee: str) -> None:
    """Add the tools to body ``ee`` and the objects of ``tasks`` to the world of ``spec``."""
    tool = spec.body(ee)
    cap = mujoco.mjtGeom.mjGEOM_CAPSULE
    box = mujoco.mjtGeom.mjGEOM_BOX
    cyl = mujoco.mjtGeom.mjGEOM_CYLINDER
    if "drilling" in tasks:
        _tool_geom(
            tool,
            DRILL_BIT,
            name=DRILL_GEOM,
            type=cap,
            fromto=[0.0, 0.0, 0.0, DRILL_LEN - DRILL_RADIUS, 0.0, 0.0],
            size=[DRILL_RADIUS, 0, 0],
        )
    if "painting" in tasks:
        _tool_geom(
            tool,
            BRUSH_BIT,
            name=BRUSH_GEOM,
            type=mujoco.mjtGeom.mjGEOM_SPHERE,
            pos=[BRUSH_AT, 0.0, 0.0],
            size=[BRUSH_RADIUS, 0, 0],
        )
    if "valve" in tasks:
        for name, y in zip(FINGER_GEOMS, (FINGER_Y, -FINGER_Y), strict=True):
            _tool_geom(
                tool,
                GRIPPER_BIT,
                name=name,
                type=cap,
                fromto=[FINGER_SPAN[0], y, 0.0, FINGER_SPAN[1], y, 0.0],
                size=[FINGER_RADIUS, 0, 0],
            )
    fx, fy, _ = layout.nominal_foot
    sr = layout.contact_solref
    if "drilling" in tasks:
        x0, x1 = layout.board_x
        board = spec.worldbody.add_body(name=BOARD)
        _object_geom(
            board,
            DRILL_BIT,
            layout.board_friction,
            sr,
            name=BOARD,
            type=box,
            size=[(x1 - x0) / 2, layout.board_half_y, 0.01],
            pos=[fx + (x0 + x1) / 2, fy, layout.board_top_z - 0.01],
            rgba=[0.7, 0.55, 0.35, 1.0],
        )
    if "painting" in tasks:
        x0, x1 = layout.panel_x
        panel = spec.worldbody.add_body(name=PANEL)
        _object_geom(
            panel,
            BRUSH_BIT,
            layout.panel_friction,
            sr,
            name=PANEL,
            type=box,
            size=[(x1 - x0) / 2, layout.panel_half_y, 0.01],
            pos=[fx + (x0 + x1) / 2, fy, layout.panel_top_z - 0.01],
            rgba=[0.9, 0.9, 0.85, 0.6],
        )
    if "valve" in tasks:
        axis = layout.valve_axis
        valve = spec.worldbody.add_body(name=VALVE, pos=[axis[0], axis[1], axis[2]])
        j = valve.add_joint(name=VALVE_JOINT, type=mujoco.mjtJoint.mjJNT_HINGE, axis=[0, 0, 1])
        j.damping = [layout.valve_damping, 0.0, 0.0]  # linear term only
        j.frictionloss = layout.valve_friction
        j.armature = 1e-3
        valve.mass = 0.3
        valve.inertia = [1e-3, 1e-3, 1e-3]
        valve.explicitinertial = True
        _object_geom(  # the handle bar the fingers straddle
            valve,
            GRIPPER_BIT,
            layout.board_friction,
            sr,
            name=HANDLE_GEOM,
            type=box,
            size=[0.06, 0.009, 0.01],
            rgba=[0.8, 0.1, 0.1, 1.0],
        )
        _object_geom(  # the hand-wheel under it
            valve,
            GRIPPER_BIT,
            layout.board_friction,
            sr,
            name="task_valve_wheel",
            type=cyl,
            size=[0.07, 0.004, 0],
            pos=[0.0, 0.0, -0.02],
            rgba=[0.6, 0.1, 0.1, 1.0],
        )
        stem = spec.worldbody.add_body(name="task_valve_stem")
        _object_geom(
            stem,
            0,
            layout.board_friction,
            sr,
            name="task_valve_stem",
            type=cyl,
            size=[0.015, (axis[2] - 0.03) / 2, 0],
            pos=[axis[0], axis[1], (axis[2] - 0.03) / 2],
        )


def enable_objects(model: mujoco.MjModel) -> int:
    """Switch the task objects' contacts on (they are off while the robot climbs to the
    ceiling through the space the objects occupy: ASSUMPTION, the objects are brought under
    the perched robot). Returns how many geoms were enabled."""
    n = 0
    for i in range(model.ngeom):
        name = model.geom(i).name
        if name.startswith("task_"):
            model.geom_conaffinity[i] = int(model.geom_user[i][0]) if model.nuser_geom else 0
            n += 1
    return n


def _ids(model: mujoco.MjModel) -> dict[str, list]:
    return {
        "body": [model.body(i).name for i in range(model.nbody)],
        "jnt": [model.joint(i).name for i in range(model.njnt)],
        "act": [model.actuator(i).name for i in range(model.nu)],
        "sensor": [model.sensor(i).name for i in range(model.nsensor)],
        "site": [model.site(i).name for i in range(model.nsite)],
    }


def add_task_objects(
    plant: Plant,
    tasks: tuple[str, ...],
    layout: TaskLayout | None = None,
    q0=None,
    base_position=(0.0, 0.0, 0.12),
) -> TaskLayout:
    """Add tools and objects to ``plant`` in place and reset it at ``q0``/``base_position``
    (what :func:`rdm.scenarios.stack.build_stack` did). Raises RuntimeError if an id the
    plant cached would move."""
    layout = layout or TaskLayout()
    before = _ids(plant.model)
    edit_spec(plant.spec, layout, tasks, plant.description.end_effector_frame)
    model = plant.spec.compile()
    after = _ids(model)
    for key, names in before.items():
        if after[key][: len(names)] != names:
            raise RuntimeError(f"add_task_objects: {key} ids moved; the plant needs a spec hook")
    geoms_env = (CEILING_GEOM, FLOOR_GEOM)
    for g in geoms_env:
        if mujoco.mj_name2id(plant.model, mujoco.mjtObj.mjOBJ_GEOM, g) != mujoco.mj_name2id(
            model, mujoco.mjtObj.mjOBJ_GEOM, g
        ):
            raise RuntimeError("add_task_objects: environment geom ids moved")
    plant.model = model
    plant.data = mujoco.MjData(model)
    env = {
        model.geom(g).id
        for g in geoms_env
        if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, g) >= 0
    }
    plant._tracker = FootContactTracker(model, plant._plate_body, env)
    plant.reset(q0=q0, base_position=base_position)
    return layout
