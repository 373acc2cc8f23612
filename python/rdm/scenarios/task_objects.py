"""Simulated objects of the perching manipulation tasks (paper Sec. VII-D, Fig. 14) and the
tools on the end effector, added to a built :class:`rdm.plant.Plant`'s MuJoCo scene.

:func:`scene` returns the ``StackOptions.scene`` / ``Plant(scene=...)`` callable that adds
tools and objects to the ``MjSpec`` before it compiles (the plant looks every id up by name
afterwards). The objects' contacts start off and :func:`enable_objects` switches them on when
the task starts (see :func:`enable_objects` for why).

Tools (ASSUMPTION: the paper swaps tools between experiments; here all three are mounted
coaxially along the end-effector x axis and collision bits make each touch only its own
object, so one perch can run every task):

* drill bit: capsule 0..``DRILL_LEN`` m, radius 5 mm (point contact at its tip);
* brush: a sphere of radius ``BRUSH_RADIUS`` centred ``BRUSH_AT`` m out (sliding contact) on
  a compliant mount: a slide joint along the tool axis (``BRUSH_JOINT``, the bristles)
  with a preloaded spring (``BRUSH_STIFFNESS``, ``BRUSH_PRELOAD``) and ``BRUSH_TRAVEL`` of
  compression, so a few mm of arm position error change the contact force by a few tenths
  of a newton instead of the servos' ~7.5 N/mm;
* gripper: four finger capsules at (y, z) = (+-``FINGER_Y``, +-``FINGER_Z``) that straddle
  the valve's handle bar on both sides of the hinge.

Objects (positions relative to the foot, see :class:`TaskLayout`; compiled around the nominal
perch spot and moved by :func:`place_objects` to the measured perched foot when the task
starts):
a horizontal wood board below the arm (drilling), a vertical wall facing the robot
(painting, the paper's) or a horizontal panel below the arm (painting-panel), and a
valve: a hand-wheel on a vertical hinge with damping and dry friction (opening resistance).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import mujoco
import numpy as np

from rdm.plant.mjcf import ROBOT_GROUP

#: Collision bits: robot links keep ROBOT_GROUP (1) and touch every object; each tool
#: touches only the object with its bit.
DRILL_BIT, BRUSH_BIT, GRIPPER_BIT = 2, 4, 8
DRILL_LEN = 0.10  # m, bit length from the tool flange
DRILL_RADIUS = 0.005
BRUSH_AT = 0.08  # m, brush centre along the tool axis with the bristles uncompressed
BRUSH_RADIUS = 0.02
#: Compliant brush (ASSUMPTION, a paint brush/roller: the bristles bend): slide joint along
#: the tool x axis, coordinate s <= 0 = compression, range [-BRUSH_TRAVEL, 0]. Spring force
#: BRUSH_PRELOAD + BRUSH_STIFFNESS * |s| pushes the brush out (held at s = 0 by the joint
#: limit when free). BRUSH_MASS is the moving brush head (not in the onboard model, like the
#: massless tools).
BRUSH_JOINT = "tool_brush_slide"
BRUSH_BODY = "tool_brush_head"
BRUSH_STIFFNESS = 100.0  # N/m
BRUSH_PRELOAD = 2.5  # N at s = 0
BRUSH_TRAVEL = 0.03  # m
BRUSH_DAMPING = 2.0  # N s/m (critical for 10 g on 100 N/m)
BRUSH_MASS = 0.01  # kg
#: Four fingers at (y, z) = (+-FINGER_Y, +-FINGER_Z) in the tool frame (z is along the handle
#: bar when the tool points down): each pair flanks the bar FINGER_Z out from the hinge, so a
#: q6 turn pushes the bar sideways. Two fingers flanking the bar at the hinge (the first
#: design) only slide along it: they engaged after acos(14/20) = 46 deg of a 69 deg turn.
#: Clearance to the bar 3 mm per side (backlash atan(3/40) = 4 deg).
FINGER_Y = 0.017  # m
FINGER_Z = 0.04  # m
FINGER_RADIUS = 0.005
FINGER_SPAN = (0.04, 0.09)  # m along the tool axis
GRIPPER_AT = 0.07  # m: where the handle bar sits between the fingers (tool axis)

BOARD = "task_board"
PANEL = "task_panel"
WALL = "task_wall"
VALVE = "task_valve"
VALVE_JOINT = "task_valve_hinge"
VALVE_STEM = "task_valve_stem"
#: The world bodies of the objects (:func:`place_objects` moves them together).
OBJECT_BODIES = (BOARD, PANEL, WALL, VALVE, VALVE_STEM)
DRILL_GEOM = "tool_drill"
BRUSH_GEOM = "tool_brush"
FINGER_GEOMS = ("tool_finger_lf", "tool_finger_rf", "tool_finger_lb", "tool_finger_rb")
HANDLE_GEOM = "task_valve_handle"


@dataclass(frozen=True)
class TaskLayout:
    """Where the objects are, relative to the nominal foot position on the ceiling.

    ASSUMPTIONS (the paper shows photos only): ``nominal_foot`` is where the perching
    scenario's foot lands (seed 0); the board, panel, wall and valve are placed inside
    the perched arm's reach in the x-z plane of the arm. Stiffness/friction: wood-like stiff
    contacts (2 ms time constant), board/valve friction 0.6, painted panel and wall 0.2 (a
    wet brush slides), valve damping 0.3 N m s/rad and dry friction 0.15 N m. The wall's face
    is the plane x = foot x + ``wall_dx`` (normal -x, toward the robot), from ``wall_bottom_z``
    up to the ceiling (the foot's z), ``wall_half_y`` either side of the foot; ``wall_dx``
    from :mod:`rdm.scenarios.wall_reach` (docs/scenarios.md "Painting a wall").
    """

    nominal_foot: tuple[float, float, float] = (0.523, 0.020, 1.600)
    board_top_z: float = 0.50  # m, world
    board_x: tuple[float, float] = (0.16, 0.40)  # relative to the foot x
    board_half_y: float = 0.15
    panel_top_z: float = 0.60  # m, world: the painted panel (horizontal, facing up)
    panel_x: tuple[float, float] = (-0.08, 0.62)  # relative to the foot x
    panel_half_y: float = 0.15
    wall_dx: float = 0.75  # m, wall face in front of the foot (x)
    wall_bottom_z: float = 0.40  # m, world
    wall_half_y: float = 0.30
    valve_x: float = 0.19  # relative to the foot x
    valve_handle_z: float = 0.48  # m, world, handle bar centre
    valve_damping: float = 0.3  # N m s/rad
    valve_friction: float = 0.15  # N m (dry friction of the stem)
    board_friction: float = 0.6
    panel_friction: float = 0.2
    contact_solref: tuple[float, float] = (0.002, 1.0)
    #: brush-panel contact: bristle tips on wet paint, softer than wood (10 ms). With the
    #: 2 ms of the board the light brush head chattered (zero-force ticks while sliding).
    panel_solref: tuple[float, float] = (0.01, 1.0)

    def around_foot(self, x: float, y: float) -> TaskLayout:
        """The same layout with its foot at world ``(x, y)`` (z, the heights, unchanged)."""
        return replace(self, nominal_foot=(float(x), float(y), self.nominal_foot[2]))

    def board_point(self, dx: float, dy: float) -> np.ndarray:
        """World point on the board's top face at (foot x + dx, foot y + dy)."""
        fx, fy, _ = self.nominal_foot
        return np.array([fx + dx, fy + dy, self.board_top_z])

    @property
    def valve_axis(self) -> np.ndarray:
        """World point of the valve hinge axis at the handle bar's height (axis = +z)."""
        fx, fy, _ = self.nominal_foot
        return np.array([fx + self.valve_x, fy, self.valve_handle_z])


#: conaffinity each object geom gets from enable_objects (robot links + its tool's bit)
_AFFINITY: dict[str, int] = {}


def _object_geom(body: mujoco.MjsBody, bits: int, friction: float, solref, **kw) -> None:
    g = body.add_geom(**kw)
    g.contype = 0
    g.conaffinity = 0  # off until enable_objects(): the robot flies up through this space
    _AFFINITY[g.name] = ROBOT_GROUP | bits
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
    if "painting" in tasks or "painting-panel" in tasks:
        head = tool.add_body(name=BRUSH_BODY, pos=[BRUSH_AT, 0.0, 0.0])
        head.mass = BRUSH_MASS
        head.inertia = [1e-6, 1e-6, 1e-6]
        head.explicitinertial = True
        j = head.add_joint(name=BRUSH_JOINT, type=mujoco.mjtJoint.mjJNT_SLIDE, axis=[1, 0, 0])
        j.stiffness = [BRUSH_STIFFNESS, 0.0, 0.0]  # linear term only
        j.springref = BRUSH_PRELOAD / BRUSH_STIFFNESS  # spring rest beyond the limit: preload
        j.damping = [BRUSH_DAMPING, 0.0, 0.0]
        j.range = [-BRUSH_TRAVEL, 0.0]
        j.limited = mujoco.mjtLimited.mjLIMITED_TRUE
        # the preload (250 m/s^2 on the head) against the default 20 ms limit let the free
        # head sit ~4 mm past its stop; 4 ms keeps it well under 1 mm
        j.solref_limit = [0.004, 1.0]
        _tool_geom(
            head,
            BRUSH_BIT,
            name=BRUSH_GEOM,
            type=mujoco.mjtGeom.mjGEOM_SPHERE,
            size=[BRUSH_RADIUS, 0, 0],
        )
    if "valve" in tasks:
        offsets = ((1, 1), (-1, 1), (1, -1), (-1, -1))
        for name, (sy, sz) in zip(FINGER_GEOMS, offsets, strict=True):
            y, z = sy * FINGER_Y, sz * FINGER_Z
            _tool_geom(
                tool,
                GRIPPER_BIT,
                name=name,
                type=cap,
                fromto=[FINGER_SPAN[0], y, z, FINGER_SPAN[1], y, z],
                size=[FINGER_RADIUS, 0, 0],
            )
    fx, fy, _ = layout.nominal_foot
    sr = layout.contact_solref

    def plate(name, bit, friction, x_range, half_y, top_z, rgba, solref=sr) -> None:
        """A 2 cm thick world plate whose top face is at ``top_z``, x relative to the foot."""
        x0, x1 = x_range
        body = spec.worldbody.add_body(name=name)
        _object_geom(
            body,
            bit,
            friction,
            solref,
            name=name,
            type=box,
            size=[(x1 - x0) / 2, half_y, 0.01],
            pos=[fx + (x0 + x1) / 2, fy, top_z - 0.01],
            rgba=rgba,
        )

    if "drilling" in tasks:
        plate(BOARD, DRILL_BIT, layout.board_friction, layout.board_x, layout.board_half_y,
              layout.board_top_z, [0.7, 0.55, 0.35, 1.0])  # fmt: skip
    if "painting" in tasks:  # the wall: 2 cm thick, its face toward the robot
        top_z = layout.nominal_foot[2]
        body = spec.worldbody.add_body(name=WALL)
        _object_geom(
            body,
            BRUSH_BIT,
            layout.panel_friction,
            layout.panel_solref,
            name=WALL,
            type=box,
            size=[0.01, layout.wall_half_y, (top_z - layout.wall_bottom_z) / 2],
            pos=[fx + layout.wall_dx + 0.01, fy, (top_z + layout.wall_bottom_z) / 2],
            rgba=[0.9, 0.9, 0.85, 0.6],
        )
    if "painting-panel" in tasks:
        plate(PANEL, BRUSH_BIT, layout.panel_friction, layout.panel_x, layout.panel_half_y,
              layout.panel_top_z, [0.9, 0.9, 0.85, 0.6], layout.panel_solref)  # fmt: skip
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
            pos=[0.0, 0.0, -0.035],  # below the finger tips (they reach -0.025)
            rgba=[0.6, 0.1, 0.1, 1.0],
        )
        stem = spec.worldbody.add_body(name=VALVE_STEM)
        _object_geom(
            stem,
            0,
            layout.board_friction,
            sr,
            name=VALVE_STEM,
            type=cyl,
            size=[0.015, (axis[2] - 0.03) / 2, 0],
            pos=[axis[0], axis[1], (axis[2] - 0.03) / 2],
        )


def enable_objects(model: mujoco.MjModel) -> int:
    """Switch the task objects' contacts on. Returns how many geoms were enabled.

    ASSUMPTION (the objects are brought under the perched robot): the robot takes off from
    the floor with the arm straight along x (x ~ 0..1 m, y ~ 0) and hangs from the ceiling
    with the tool reaching only that same x-z band below the foot (q3 stays 0 for the
    levelled vectoring units), so every place the tool can reach was crossed by the arm on
    the way up; objects there would be hit during the climb."""
    n = 0
    for i in range(model.ngeom):
        name = model.geom(i).name
        if name in _AFFINITY:
            model.geom_conaffinity[i] = _AFFINITY[name]
            # MuJoCo's broad phase filters body pairs first with the per-body OR of the
            # geoms' bits, computed at compile time (0 here): update it too
            body = model.geom_bodyid[i]
            model.body_conaffinity[body] |= _AFFINITY[name]
            n += 1
    return n


def place_objects(model: mujoco.MjModel, compiled: TaskLayout, placed: TaskLayout) -> int:
    """Move the objects compiled around ``compiled``'s foot so they sit around ``placed``'s
    foot (a translation in x, y). Returns how many bodies moved.

    ASSUMPTION (as :func:`enable_objects`: the objects are brought under the perched robot):
    they are placed relative to where the foot actually perched, not to a fixed world spot.
    The foot lands within a few cm of its planned point (docs/scenarios.md), and the valve's
    workable window is only about -15..+10 mm of foot position, so a fixed placement makes the
    outcome depend on the landing. Call it while the objects' contacts are still off."""
    dx = placed.nominal_foot[0] - compiled.nominal_foot[0]
    dy = placed.nominal_foot[1] - compiled.nominal_foot[1]
    n = 0
    for name in OBJECT_BODIES:
        try:
            body = model.body(name)
        except KeyError:
            continue  # this task's scene has no such object
        model.body_pos[body.id, 0] += dx
        model.body_pos[body.id, 1] += dy
        n += 1
    return n


def scene(tasks: tuple[str, ...], layout: TaskLayout | None = None, ee: str = "end_effector"):
    """The ``scene`` callable (``StackOptions.scene``) that adds the tools of ``tasks`` to body
    ``ee`` and their objects to the world."""
    lay = layout or TaskLayout()

    def edit(spec: mujoco.MjSpec) -> None:
        edit_spec(spec, lay, tasks, ee)

    return edit
