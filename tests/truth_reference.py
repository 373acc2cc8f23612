"""The plant's ground truth derived directly from MuJoCo, the tests' oracle for
``Plant.ground_truth`` and ``FootContactTracker.measure``.

Every number comes from MuJoCo's own quantities: the contact list read one ``data.contact[i]``
object at a time, ``mj_contactForce``, fresh numpy copies of ``xpos``, ``xquat``, ``qvel``,
``subtree_com`` and ``mju_mat2Quat``; the frame products are summed in index order
(``(a0 b0 + a1 b1) + a2 b2``, the order the plant documents in docs/plant.md "Same bits on
any BLAS"), the cross products are ``np.cross``. The first-contact anchor is the tracker's
(its bookkeeping runs once per call, as in the plant's own measurement).
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from rdm.plant import Plant
from rdm.plant.truth import FootContactTracker, GroundTruth


def _t_mul(m: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``m.T @ v`` summed over ``m``'s rows in index order."""
    return np.array(
        [(m[0, j] * v[0] + m[1, j] * v[1]) + m[2, j] * v[2] for j in range(3)], dtype=float
    )


def _dot(a: np.ndarray, b: np.ndarray) -> float:
    return float((a[0] * b[0] + a[1] * b[1]) + a[2] * b[2])


def _yaw(normal: np.ndarray, r0: np.ndarray, r1: np.ndarray) -> float:
    """Angle of the rotation r0 -> r1 about ``normal`` (x axes projected on the plane)."""
    x0 = r0[:, 0] - normal * _dot(r0[:, 0], normal)
    x1 = r1[:, 0] - normal * _dot(r1[:, 0], normal)
    return math.atan2(_dot(normal, np.cross(x0, x1)), _dot(x0, x1))


def measure_reference(
    tracker: FootContactTracker, data: mujoco.MjData
) -> tuple[int, np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]:
    """(points, force, torque, zmp, slip, slip_yaw) of the plate's present contacts: what the
    robot applies to the environment, in the plate frame, moments about its origin."""
    m = tracker._model
    pb = tracker._plate_body
    env = tracker._env_geoms
    origin = data.xpos[pb]
    rot = data.xmat[pb].reshape(3, 3)
    force_w = np.zeros(3)  # environment on robot, world
    torque_w = np.zeros(3)
    cop_num = np.zeros(3)
    normal_sum = 0.0
    points = 0
    buf = np.zeros(6)
    for i in range(data.ncon):
        c = data.contact[i]
        b1, b2 = m.geom_bodyid[c.geom1], m.geom_bodyid[c.geom2]
        if b1 == pb and c.geom2 in env:
            sign = -1.0  # MuJoCo's force acts on geom2 from geom1: the plate is geom1
        elif b2 == pb and c.geom1 in env:
            sign = 1.0
        else:
            continue
        mujoco.mj_contactForce(m, data, i, buf)
        frame = c.frame.reshape(3, 3)  # rows: normal, tangent1, tangent2
        f = sign * _t_mul(frame, buf[:3])
        t = sign * _t_mul(frame, buf[3:])
        force_w += f
        torque_w += t + np.cross(c.pos - origin, f)
        n = abs(buf[0])
        cop_num += n * (c.pos - origin)
        normal_sum += n
        points += 1
    force = -_t_mul(rot, force_w)
    torque = -_t_mul(rot, torque_w)
    tracker._track(data, points > 0)
    zmp = _t_mul(rot, cop_num / normal_sum)[:2] if normal_sum > 0 else np.full(2, np.nan)
    if tracker.anchor_pos is None or tracker.anchor_rot is None:
        return points, force, torque, zmp, np.zeros(2), 0.0
    anchor_rot = tracker.anchor_rot
    slip = (origin - tracker.anchor_pos)[:2]
    return points, force, torque, zmp, slip.copy(), _yaw(anchor_rot[:, 2], anchor_rot, rot)


def ground_truth_reference(plant: Plant) -> GroundTruth:
    """The plant's true state now, from fresh MjData copies and :func:`measure_reference`."""
    d = plant._fresh()
    points, force, torque, zmp, slip, yaw = measure_reference(plant._tracker, d)
    fb = plant._foot_body
    ee = plant._ee_body
    if plant.options.fixed_base:
        lin, ang = np.zeros(3), np.zeros(3)
    else:
        lin, ang = d.qvel[0:3].copy(), d.qvel[3:6].copy()
    ee_quat = np.zeros(4)
    mujoco.mju_mat2Quat(ee_quat, d.xmat[ee])
    return GroundTruth(
        time=float(d.time),
        base_position=d.xpos[fb].copy(),
        base_quaternion=d.xquat[fb].copy(),
        base_linear_velocity=lin,
        base_angular_velocity=ang,
        joint_positions=d.qpos[plant._qadr],
        joint_velocities=d.qvel[plant._vadr],
        cog_position=d.subtree_com[fb].copy(),
        end_effector_position=d.xpos[ee].copy(),
        end_effector_quaternion=ee_quat,
        rotor_thrusts=plant.rotor_thrusts(),
        foot_in_contact=points > 0,
        foot_contact_points=points,
        foot_contact_force=force,
        foot_contact_torque=torque,
        foot_zmp=zmp,
        foot_slip=slip,
        foot_slip_yaw=yaw,
    )
