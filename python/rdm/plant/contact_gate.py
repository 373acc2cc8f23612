"""The plant's collision gate: skip MuJoCo's collision detection while no contact can occur.

MuJoCo runs its broad and narrow phase in every position pass, ~3 us a step here, also while
the robot flies a metre from the floor and the ceiling. After each step the gate proves from
the state at hand that the next pass cannot produce a contact, and then sets
``mjDSBL_CONTACT`` for it (``mj_collision`` returns at once). A pass without contacts computes
the same numbers with and without the flag, so runs stay bit-for-bit the same
(``tests/test_contact_gate.py`` checks it against a plant without the gate).

The proof (``rdm_core::sim::contact_gate``): every moving geom lies inside its bounding sphere
(``geom_rbound`` about ``geom_xpos``); no point of the robot moves further in one step than
``dt * (|v| + |w| rho + sum_j |qdot_j| L_j)`` (the free joint's speeds, ``rho`` the farthest
geom surface from the root body's origin, ``L_j`` a hinge anchor's distance to it plus
``rho``), plus a slack. Contacts stay off while every colliding pair's gap (distance to the
obstacle - rbound - the pair's margins) exceeds that reach.

Where it applies: every pair that can collide (``contype``/``conaffinity``) is a geom of the
robot's tree (one free joint at its root, hinges and slides below) against a static plane or
box. Anything else (explicit ``<pair>`` elements, other moving trees, mesh obstacles, a fixed
base, the tasks' scenes whose objects move by editing the model) builds no gate: contacts
stay on, as before. The gate reads the obstacles' poses, sizes, margins and contact bits once,
from the compiled model: code that edits them later (``model.geom_pos`` of the ceiling, say)
builds its plant with ``contact_gate=False``.

ASSUMPTION (docs/plant.md "The collision gate"): a slack of 1 cm. It covers what the linear
bound leaves out over one step (the change of the lever arms, of the rotation) with a wide
margin: at the robot's speeds (< 5 m/s, < 10 rad/s) one step moves a point by a few mm.
"""

from __future__ import annotations

import mujoco

from rdm._rdm import ContactGateCore

#: Extra reach [m] beyond the one-step bound (see the module docstring).
GATE_SLACK = 0.01

_FREE = int(mujoco.mjtJoint.mjJNT_FREE)
_HINGE = int(mujoco.mjtJoint.mjJNT_HINGE)
_SLIDE = int(mujoco.mjtJoint.mjJNT_SLIDE)
_PLANE = int(mujoco.mjtGeom.mjGEOM_PLANE)
_BOX = int(mujoco.mjtGeom.mjGEOM_BOX)
_CONTACT_BIT = int(mujoco.mjtDisableBit.mjDSBL_CONTACT)


def _collide(m: mujoco.MjModel, a: int, b: int) -> bool:
    """MuJoCo's contype/conaffinity filter (the parent filter is left out: more pairs is safe)."""
    return bool(
        (m.geom_contype[a] & m.geom_conaffinity[b]) or (m.geom_contype[b] & m.geom_conaffinity[a])
    )


def _tree(m: mujoco.MjModel, root_body: int) -> tuple[set[int], list[int]]:
    """The bodies of the tree rooted at ``root_body`` and its joints."""
    tree = {b for b in range(m.nbody) if m.body_rootid[b] == root_body}
    return tree, [j for j in range(m.njnt) if m.jnt_bodyid[j] in tree]


def _static_geoms(m: mujoco.MjModel) -> list[bool]:
    """Per geom: welded to the world (it never moves)."""
    return [int(m.body_weldid[m.geom_bodyid[g]]) == 0 for g in range(m.ngeom)]


def gate_refusal(m: mujoco.MjModel, root_body: int) -> str | None:
    """Why a model gets no gate (None: it does). ``root_body`` is the robot's root body."""
    if m.npair:
        return "explicit contact pairs"
    if m.opt.disableflags & _CONTACT_BIT:
        return "contacts already disabled"
    in_tree, joints = _tree(m, root_body)
    free = [j for j in joints if m.jnt_type[j] == _FREE]
    if len(free) != 1 or m.jnt_bodyid[free[0]] != root_body:
        return "the robot's root is not one free joint"
    if any(m.jnt_type[j] not in (_FREE, _HINGE, _SLIDE) for j in joints):
        return "a ball joint in the robot"
    static = _static_geoms(m)
    for a in range(m.ngeom):
        for b in range(a + 1, m.ngeom):
            if not _collide(m, a, b) or m.geom_bodyid[a] == m.geom_bodyid[b]:
                continue
            if static[a] and static[b]:
                continue
            if not static[a] and not static[b]:
                return "two moving geoms can collide"
            moving, fixed = (b, a) if static[a] else (a, b)
            if int(m.geom_bodyid[moving]) not in in_tree:
                return "a moving geom outside the robot can collide"
            if int(m.geom_type[fixed]) not in (_PLANE, _BOX):
                return "an obstacle that is neither a plane nor a box"
    return None


def build_contact_gate(
    m: mujoco.MjModel, d: mujoco.MjData, root_body: int, slack: float = GATE_SLACK
) -> ContactGateCore | None:
    """The gate of plant model ``m`` (reading ``d``'s views), or None where it does not apply
    (:func:`gate_refusal`). Obstacle poses come from a separate MjData (static bodies)."""
    if gate_refusal(m, root_body) is not None:
        return None
    scratch = mujoco.MjData(m)
    mujoco.mj_kinematics(m, scratch)
    static = _static_geoms(m)
    moving = [g for g in range(m.ngeom) if not static[g]]
    obstacles = [g for g in range(m.ngeom) if static[g] and any(_collide(m, g, k) for k in moving)]
    planes = [o for o in obstacles if m.geom_type[o] == _PLANE]
    boxes = [o for o in obstacles if m.geom_type[o] == _BOX]
    order = planes + boxes
    plane_specs = [
        (scratch.geom_xpos[o].tolist(), scratch.geom_xmat[o].reshape(3, 3)[:, 2].tolist())
        for o in planes
    ]
    box_specs = [
        (scratch.geom_xpos[o].tolist(), scratch.geom_xmat[o].tolist(), m.geom_size[o].tolist())
        for o in boxes
    ]
    geoms = []
    for g in moving:
        margins = [
            float(m.geom_margin[g] + m.geom_margin[o]) if _collide(m, g, o) else None for o in order
        ]
        if any(x is not None for x in margins):
            geoms.append((g, float(m.geom_rbound[g]), margins))
    _, joints = _tree(m, root_body)
    free = next(j for j in joints if m.jnt_type[j] == _FREE)
    hinges = [(j, int(m.jnt_dofadr[j])) for j in joints if m.jnt_type[j] == _HINGE]
    slides = [int(m.jnt_dofadr[j]) for j in joints if m.jnt_type[j] == _SLIDE]
    return ContactGateCore(
        float(m.opt.timestep),
        slack,
        plane_specs,
        box_specs,
        geoms,
        int(m.jnt_dofadr[free]),
        hinges,
        slides,
        root_body,
        m.opt,
        _CONTACT_BIT,
        d.geom_xpos,
        d.xpos,
        d.xanchor,
        d.qvel,
    )
