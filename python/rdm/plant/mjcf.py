"""Generate the MuJoCo model (an :class:`mujoco.MjSpec`) of a robot from its description.

Steps, all on the spec MuJoCo's own URDF importer returns:

1. import the URDF (fixed-joint frames kept: ``fusestatic=false``; inertias from the URDF
   ``<inertial>`` tags only, never from geoms);
2. give the root link (the foot) a free joint, unless ``fixed_base`` (bench tests);
3. move the foot plate collision box into a massless child body ``foot_plate`` whose frame
   is the foot frame, so a MuJoCo force/torque sensor there measures exactly what the
   Leptrino between plate and foot module measures; likewise the end-effector frame;
4. position servos on every joint of ``joint_order`` (torque limited to the stall torque);
5. one ``general`` actuator per rotor on a site whose z axis is the rotor axis:
   ``ctrl`` = thrust [N], gear [0, 0, 1, 0, 0, -sigma c] gives thrust along z and the drag
   torque -sigma_i c lambda_i u_i of eq. (9);
6. sensors (IMU at the root-link tip where the processor sits, wrench sensors), the
   ceiling (a static box whose lower face is the ceiling plane) and optionally a floor.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import mujoco
import numpy as np

from rdm.plant.description import DescriptionError, RobotDescription
from rdm.plant.servo import ServoParams

ROBOT_GROUP = 1  # contype of robot geoms: they touch the environment, never each other
ENV_GROUP = 1  # conaffinity of environment geoms
FOOT_PLATE_BODY = "foot_plate"
CEILING_GEOM = "ceiling"
FLOOR_GEOM = "floor"
#: World geoms named with this prefix (added by a scene, e.g. the wall-perching plate) are
#: contact surfaces of the foot like the ceiling: the ground truth's foot contact wrench and
#: slip count their contacts (the ZMP there assumes the ceiling's normal).
CONTACT_SURFACE_PREFIX = "contact_surface"
IMU_SITE = "imu"
CEILING_HALF_THICKNESS = 0.05


def rotor_site(name: str) -> str:
    """Site name of a rotor."""
    return f"{name}_site"


def rotor_actuator(name: str) -> str:
    """Actuator name of a rotor."""
    return f"{name}_thrust"


def servo_actuator(joint: str) -> str:
    """Actuator name of a joint's servo."""
    return f"{joint}_servo"


def wrench_site(sensor: str) -> str:
    """Site name of a wrench sensor."""
    return f"{sensor}_site"


@dataclass(frozen=True)
class ContactParams:
    """Contact model of the ceiling/foot interface (ASSUMPTIONS, see docs/plant.md).

    ``friction``: sliding mu (Table VII mu_x = mu_y); ``torsional``: MuJoCo's torsional
    coefficient [m] per contact point (condim 4), default Table VII mu_z; ``solref`` /
    ``solimp``: a stiff, critically damped contact (10 ms time constant) so a perched foot
    sits still; ``impratio`` > 1 makes friction stiffer than the normal direction, so a
    push below mu N creeps by micrometres only.
    """

    friction: float = 0.9
    torsional: float = 0.5
    rolling: float = 1e-4
    condim: int = 4
    solref: tuple[float, float] = (0.01, 1.0)
    solimp: tuple[float, float, float, float, float] = (0.95, 0.99, 0.001, 0.5, 2.0)
    impratio: float = 10.0


@dataclass(frozen=True)
class BuildOptions:
    """What the generated model contains besides the robot."""

    timestep: float = 0.001
    ceiling_height: float | None = 2.0
    floor_height: float | None = None
    fixed_base: bool = False
    servo: ServoParams = field(default_factory=ServoParams)
    contact: ContactParams | None = None  # None: friction from the robot's TOML
    ceiling_max_ratio: float = 1.5  # rotor ctrlrange = thrust_max * this (ceiling gain)
    magnetic_field: tuple[float, float, float] = (30.0, 0.0, -35.0)  # uT, ASSUMPTION


def _quat_z_to(axis: tuple[float, float, float]) -> np.ndarray:
    """Unit quaternion (w, x, y, z) rotating +z onto ``axis``."""
    a = np.asarray(axis, dtype=float)
    n = np.linalg.norm(a)
    if not np.isfinite(n) or n < 1e-9:
        raise DescriptionError(f"rotors.axis: not a direction {axis}")
    a = a / n
    z = np.array([0.0, 0.0, 1.0])
    c = float(z @ a)
    if c < -1.0 + 1e-12:
        return np.array([0.0, 1.0, 0.0, 0.0])
    v = np.cross(z, a)
    q = np.array([1.0 + c, *v])
    return q / np.linalg.norm(q)


def _body(spec: mujoco.MjSpec, name: str) -> mujoco.MjsBody:
    body = spec.body(name)
    if body is None:
        raise DescriptionError(f"URDF: no link named {name!r}")
    return body


def _joint_range(spec: mujoco.MjSpec, name: str) -> np.ndarray:
    joint = spec.joint(name)
    if joint is None:
        raise DescriptionError(f"joint_order: URDF has no joint named {name!r}")
    return np.array(joint.range, dtype=float)


def _style_robot_geoms(spec: mujoco.MjSpec, contact: ContactParams) -> None:
    for geom in spec.geoms:
        geom.contype = ROBOT_GROUP
        geom.conaffinity = 0
        geom.condim = contact.condim
        geom.friction = [contact.friction, contact.torsional, contact.rolling]
        geom.solref = list(contact.solref)
        geom.solimp = list(contact.solimp)
        geom.density = 0.0  # masses come from the URDF inertials only


def add_env_geom(spec: mujoco.MjSpec, contact: ContactParams, **kwargs: object) -> None:
    """Adds a world geom (``kwargs``: MuJoCo's ``add_geom`` arguments) that the robot's links
    touch with the environment's contact parameters (the ceiling, the floor, a task's wall)."""
    geom = spec.worldbody.add_geom(**kwargs)
    geom.contype = 0
    geom.conaffinity = ENV_GROUP
    geom.condim = contact.condim
    geom.priority = 1
    geom.friction = [contact.friction, contact.torsional, contact.rolling]
    geom.solref = list(contact.solref)
    geom.solimp = list(contact.solimp)


def build_spec(desc: RobotDescription, options: BuildOptions | None = None) -> mujoco.MjSpec:
    """Build the plant's MjSpec; ``spec.compile()`` gives the model, ``spec.to_xml()`` MJCF."""
    opt = options or BuildOptions()
    contact = opt.contact or ContactParams(friction=desc.friction_xy, torsional=desc.friction_z)
    spec = mujoco.MjSpec.from_file(str(desc.urdf_path))
    spec.modelname = desc.name
    spec.compiler.fusestatic = False
    spec.compiler.discardvisual = False
    spec.compiler.inertiafromgeom = mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_FALSE
    spec.option.timestep = opt.timestep
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    spec.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    spec.option.impratio = contact.impratio
    spec.option.magnetic = list(opt.magnetic_field)

    foot = _body(spec, desc.foot_frame)
    if not opt.fixed_base:
        foot.add_freejoint(name="base")

    # The foot plate: a massless body at the foot frame carrying the contact box(es).
    plate = foot.add_body(name=FOOT_PLATE_BODY)
    for geom in list(foot.geoms):
        plate.add_geom(
            name="foot_plate_box", type=geom.type, size=geom.size, pos=geom.pos, quat=geom.quat
        )
        spec.delete(geom)
    _style_robot_geoms(spec, contact)

    # Servos, in joint_order.
    for name in desc.joint_order:
        rng = _joint_range(spec, name)
        joint = spec.joint(name)
        joint.armature = opt.servo.armature
        # The URDF importer turns <limit effort> into a joint-level clamp on ALL actuator
        # forces at the joint, rotor thrust included; the servo's forcerange is the limit.
        joint.actfrclimited = mujoco.mjtLimited.mjLIMITED_FALSE
        joint.frictionloss = opt.servo.frictionloss
        stall = desc.joint(name).stall_torque
        act = spec.add_actuator(name=servo_actuator(name), target=name)
        act.trntype = mujoco.mjtTrn.mjTRN_JOINT
        act.gaintype = mujoco.mjtGain.mjGAIN_FIXED
        act.gainprm[0] = opt.servo.kp
        act.biastype = mujoco.mjtBias.mjBIAS_AFFINE
        act.biasprm[0:3] = [0.0, -opt.servo.kp, -opt.servo.kv]
        act.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
        act.ctrlrange = rng
        act.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
        act.forcerange = [-stall, stall]
        if opt.servo.goal_filter_s > 0:
            # The loop's reference is the filter state (act), first-order toward ctrl.
            act.dyntype = mujoco.mjtDyn.mjDYN_FILTEREXACT
            act.dynprm[0] = opt.servo.goal_filter_s

    # Rotors: thrust + drag torque on a site whose z axis is the rotor axis.
    for rotor in desc.rotors:
        parent = _body(spec, rotor.parent)
        parent.add_site(
            name=rotor_site(rotor.name),
            pos=list(rotor.offset),
            quat=list(_quat_z_to(rotor.axis)),
            size=[0.01, 0.01, 0.01],
        )
        act = spec.add_actuator(name=rotor_actuator(rotor.name), target=rotor_site(rotor.name))
        act.trntype = mujoco.mjtTrn.mjTRN_SITE
        act.gear = [0.0, 0.0, 1.0, 0.0, 0.0, -rotor.spin * rotor.drag_to_thrust]
        act.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
        act.ctrlrange = [0.0, rotor.thrust_max * opt.ceiling_max_ratio]

    # IMU at the root-link tip: the origin of the child body that carries q2.
    imu_body, imu_pos = _imu_mount(spec, desc)
    imu_body.add_site(name=IMU_SITE, pos=imu_pos, size=[0.01, 0.01, 0.01])
    _site_sensor(spec, "gyro", mujoco.mjtSensor.mjSENS_GYRO, IMU_SITE)
    _site_sensor(spec, "accelerometer", mujoco.mjtSensor.mjSENS_ACCELEROMETER, IMU_SITE)
    _site_sensor(spec, "magnetometer", mujoco.mjtSensor.mjSENS_MAGNETOMETER, IMU_SITE)

    # Wrench sensors: the foot one on the plate body, others on their frame's body.
    for key, sensor in desc.wrench_sensors.items():
        body = plate if sensor.frame == desc.foot_frame else _body(spec, sensor.frame)
        body.add_site(name=wrench_site(key), size=[0.01, 0.01, 0.01])
        _site_sensor(spec, f"{key}_force", mujoco.mjtSensor.mjSENS_FORCE, wrench_site(key))
        _site_sensor(spec, f"{key}_torque", mujoco.mjtSensor.mjSENS_TORQUE, wrench_site(key))

    if opt.ceiling_height is not None:
        add_env_geom(
            spec,
            contact,
            name=CEILING_GEOM,
            type=mujoco.mjtGeom.mjGEOM_BOX,
            size=[5.0, 5.0, CEILING_HALF_THICKNESS],
            pos=[0.0, 0.0, opt.ceiling_height + CEILING_HALF_THICKNESS],
            rgba=[0.6, 0.6, 0.7, 0.4],
        )
    if opt.floor_height is not None:
        add_env_geom(
            spec,
            contact,
            name=FLOOR_GEOM,
            type=mujoco.mjtGeom.mjGEOM_PLANE,
            size=[5.0, 5.0, 0.1],
            pos=[0.0, 0.0, opt.floor_height],
        )
    spec.worldbody.add_light(pos=[0.0, 0.0, 1.0], dir=[0.0, 0.0, -1.0])
    return spec


def _site_sensor(spec: mujoco.MjSpec, name: str, kind: mujoco.mjtSensor, site: str) -> None:
    spec.add_sensor(name=name, type=kind, objtype=mujoco.mjtObj.mjOBJ_SITE, objname=site)


def _imu_mount(spec: mujoco.MjSpec, desc: RobotDescription) -> tuple[mujoco.MjsBody, list[float]]:
    """Body and position of the processor: root link (q1's child) at q2's mount point."""
    q1 = spec.joint(desc.joint_order[0])
    q2 = spec.joint(desc.joint_order[1])
    if q1 is None or q2 is None:
        raise DescriptionError("joint_order: the first two joints must exist in the URDF")
    root_link = q1.parent
    q2_body = q2.parent
    if q2_body.parent.name != root_link.name:
        raise DescriptionError("URDF: q2 must connect the root link to the next link")
    return root_link, [float(x) for x in q2_body.pos]


def build_model(desc: RobotDescription, options: BuildOptions | None = None) -> mujoco.MjModel:
    """Compile the plant model."""
    return build_spec(desc, options).compile()
