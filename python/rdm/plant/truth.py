"""Ground truth for metrics: base state, joints, foot contact wrench, slip and ZMP.

Contact quantities are computed from MuJoCo's contact list (``mj_contactForce``), not from
the wrench sensors, so metrics can compare a controller's estimate with the truth.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

from rdm import _rdm

#: The cone whose contact forces ``mj_contactForce`` decodes from pyramid forces.
_PYRAMIDAL = mujoco.mjtCone.mjCONE_PYRAMIDAL


@dataclass(frozen=True)
class GroundTruth:
    """The true state of the plant at ``time``.

    Wrenches follow the wrench sensors' convention: what the robot applies to the
    environment, in the foot frame (z out of the contact face), moments about its origin.
    """

    time: float
    base_position: np.ndarray  # foot frame origin, world [m]
    base_quaternion: np.ndarray  # foot frame orientation (w, x, y, z), world
    base_linear_velocity: np.ndarray  # world frame [m/s]
    base_angular_velocity: np.ndarray  # foot (body) frame [rad/s]
    joint_positions: np.ndarray  # joint_order
    joint_velocities: np.ndarray  # joint_order
    cog_position: np.ndarray  # whole robot, world
    end_effector_position: np.ndarray  # world
    end_effector_quaternion: np.ndarray  # (w, x, y, z), world
    rotor_thrusts: np.ndarray  # applied thrust incl. ceiling effect [N]
    foot_in_contact: bool
    foot_contact_points: int
    foot_contact_force: np.ndarray  # foot frame [N]
    foot_contact_torque: np.ndarray  # foot frame, about the plate centre [N m]
    foot_zmp: np.ndarray  # centre of pressure (x, y) in the foot frame; NaN off contact
    foot_slip: np.ndarray  # (x, y) world displacement of the foot since first contact [m]
    # (kept through contact gaps < 0.1 s; zero when there is no contact anchor)
    foot_slip_yaw: float  # rotation about the ceiling normal since first contact [rad]


#: The :class:`GroundTruth` field names in field order.
TRUTH_FIELDS = tuple(GroundTruth.__dataclass_fields__)
#: Read-only constants of the no-contact measurement.
_ZEROS3 = np.zeros(3)
_ZEROS3.flags.writeable = False
_NAN2 = np.full(2, np.nan)
_NAN2.flags.writeable = False
#: ``FootTrackerCore.update``'s answers: build the contact view, set the anchor.
_NEEDS_VIEW = 1
_NEEDS_ANCHOR = 2


def _dot3(a: np.ndarray, b: np.ndarray) -> float:
    """``a @ b`` of two float64 3-vectors summed left to right, ``(a0 b0 + a1 b1) + a2 b2``.
    numpy's ``@`` may go through BLAS, whose kernels on some CPUs fuse a product into the
    sum (one rounding less) or sum in another order; this order is the one every form of the
    measurement and the Rust core share, on any machine."""
    a0, a1, a2 = a.tolist()
    b0, b1, b2 = b.tolist()
    return a0 * b0 + a1 * b1 + a2 * b2


def _t_mul(m: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``m.T @ v`` for a 3x3 ``m`` and a 3-vector, each component summed over ``m``'s rows
    in order (:func:`_dot3`'s order, not BLAS's)."""
    (a0, a1, a2), (b0, b1, b2), (c0, c1, c2) = m.tolist()
    v0, v1, v2 = v.tolist()
    return np.array(
        (a0 * v0 + b0 * v1 + c0 * v2, a1 * v0 + b1 * v1 + c1 * v2, a2 * v0 + b2 * v1 + c2 * v2)
    )


def _yaw_about(normal: np.ndarray, r0: np.ndarray, r1: np.ndarray) -> float:
    """Angle of the rotation r0 -> r1 about ``normal`` (x axes projected on the plane)."""
    x0 = r0[:, 0] - normal * _dot3(r0[:, 0], normal)
    x1 = r1[:, 0] - normal * _dot3(r1[:, 0], normal)
    return math.atan2(_dot3(normal, _cross3(x0, x1)), _dot3(x0, x1))


def _cross3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``np.cross(a, b)`` of two float64 3-vectors: numpy computes each component as
    ``a1 * b2 - a2 * b1`` (one rounded product, another, a rounded difference), so do Python
    floats, with the same bits; a NaN in the result (where NaN payloads could differ) takes
    ``np.cross`` itself (tests/test_truthlog_truth.py)."""
    a0, a1, a2 = a.tolist()
    b0, b1, b2 = b.tolist()
    c0 = a1 * b2 - a2 * b1
    c1 = a2 * b0 - a0 * b2
    c2 = a0 * b1 - a1 * b0
    if c0 != c0 or c1 != c1 or c2 != c2:
        return np.cross(a, b)
    return np.array((c0, c1, c2))


class FootContactTracker:
    """Sums the foot plate's contact forces and remembers where contact started.

    The first-contact anchor survives contact gaps shorter than ``release_time`` (a sliding
    or vibrating foot chatters on and off the surface); after a longer gap the next
    contact starts a new anchor.
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        plate_body: int,
        env_geoms: set[int],
        release_time: float = 0.1,
    ) -> None:
        self._model = model
        self._plate_body = plate_body
        self._env_geoms = env_geoms
        self._views: tuple = (None, None, None)  # (data, its xpos, its xmat)
        plate_geoms = sorted(np.flatnonzero(model.geom_bodyid == plate_body).tolist())
        #: The anchor, the last contact time and the cached contact view, in Rust (the one
        #: object this face and the lockstep kernel's plant step both update).
        self._core = _rdm.FootTrackerCore(plate_geoms, release_time)
        #: :meth:`measure_contacts` in Rust
        self._sums_core = _rdm.PlateContactCore(
            model.geom_bodyid.tolist(),
            [g in env_geoms for g in range(model.ngeom)],
            plate_body,
        )

    @property
    def release_time(self) -> float:
        """Longest contact gap [s] the first-contact anchor survives."""
        return self._core.release_time

    @release_time.setter
    def release_time(self, seconds: float) -> None:
        self._core.release_time = seconds

    @property
    def last_contact_time(self) -> float:
        """The last time the plate touched an environment surface (-inf: none since the
        last release)."""
        return self._core.last_contact_time

    @property
    def anchor_pos(self) -> np.ndarray | None:
        """The plate's world position at first contact (a copy), or None."""
        return self._core.anchor_pos

    @property
    def anchor_rot(self) -> np.ndarray | None:
        """The plate's rotation matrix at first contact (a copy), or None."""
        return self._core.anchor_rot

    @property
    def view_misses(self) -> int:
        """Times a cached contact view was found pointing elsewhere (see :meth:`update`)."""
        return self._core.view_misses

    def update(self, data: mujoco.MjData) -> None:
        """Per-step bookkeeping of the first-contact anchor (cheap: no contact forces).

        MuJoCo keeps the contact list at the start of mjData's arena, so the
        ``data.contact.geom`` view (~5 us to build through the bindings) is built again only
        when ``ncon`` changes (its address is re-checked at every :meth:`measure`; a moved
        list is counted in ``view_misses`` and read again)."""
        core = self._core
        ncon = data.ncon
        status = core.update(data, ncon, data.time)
        if status == _NEEDS_VIEW:
            geom = data.contact.geom
            core.keep_view(data, ncon, geom.__array_interface__["data"][0], geom)
            status = core.update(data, ncon, data.time)
        if status == _NEEDS_ANCHOR:
            self._anchor(data)

    def idle(self) -> bool:
        """No contact anchor and no contact time to release: :meth:`measure` of an empty
        contact list then changes nothing and gives fixed numbers (no contact, -(R.T @ 0)
        force and torque, NaN ZMP, zero slip and yaw)."""
        return self._core.idle()

    def plate_contact(self, data: mujoco.MjData) -> bool:
        """Whether a present contact involves a plate geom (:meth:`measure_contacts` sums
        only such contacts: without one it gives the numbers of an empty contact list).
        Runs :meth:`measure`'s view check first (the same ``view_misses``); reads the cached
        contact view when it is this list's."""
        self._check_view(data)
        ncon = data.ncon
        if not ncon:
            return False
        geom = self._core.view_of(data, ncon)
        return self._core.plate_in(data.contact.geom if geom is None else geom)

    def _check_view(self, data: mujoco.MjData) -> None:
        """Drop the cached contact view if the list has moved (counted in ``view_misses``)."""
        core = self._core
        ncon = data.ncon
        if (
            ncon
            and core.view_of(data, ncon) is not None
            and data.contact.geom.__array_interface__["data"][0] != core.view_address
        ):
            core.forget_view()

    def _track(self, data: mujoco.MjData, in_contact: bool) -> None:
        if self._core.track(float(data.time), in_contact):
            self._anchor(data)

    def _anchor(self, data: mujoco.MjData) -> None:
        """The plate's present pose as the first-contact anchor."""
        pb = self._plate_body
        self._core.set_anchor(data.xpos[pb], data.xmat[pb])

    def reset(self) -> None:
        """Forget the first-contact anchor."""
        self._core.reset()

    def measure(
        self, data: mujoco.MjData
    ) -> tuple[int, np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]:
        """(points, force, torque, zmp, slip, slip_yaw) for the present contacts.

        No contact at all (a flying robot): the numbers of an empty contact list (no
        points, -(R.T @ 0) force and torque, NaN ZMP) and the anchor's slip and yaw."""
        if data.ncon:
            return self.measure_contacts(data)
        if self._views[0] is not data:
            self._views = (data, data.xpos, data.xmat)  # stable for the data's lifetime
        _, xpos, xmat = self._views
        pb = self._plate_body
        rot = xmat[pb].reshape(3, 3)
        # -(rot.T @ zeros) for the force and the torque: one product.
        force = -_t_mul(rot, _ZEROS3)
        torque = force.copy()
        core = self._core
        if not core.idle():
            self._track(data, False)
        zmp = _NAN2.copy()
        anchor_pos, anchor_rot = core.anchor_pos, core.anchor_rot
        if anchor_pos is None or anchor_rot is None:
            return 0, force, torque, zmp, np.zeros(2), 0.0
        origin = xpos[pb]
        slip = (origin - anchor_pos)[:2]
        yaw = _yaw_about(anchor_rot[:, 2], anchor_rot, rot)
        return 0, force, torque, zmp, slip.copy(), yaw

    def measure_contacts(
        self, data: mujoco.MjData
    ) -> tuple[int, np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]:
        """(points, force, torque, zmp, slip, slip_yaw) of the plate's present contacts, in
        Rust (``rdm._rdm.PlateContactCore``): per plate contact the force ``mj_contactForce``
        gives (an elliptic cone's constraint forces copied from ``efc_force``, a pyramidal
        cone's decoded), rotated out of the contact frame and summed into force, torque about
        the plate origin and the centre of pressure, reported in the plate frame, and the
        slip yaw; products summed in index order (no fused multiply-add)."""
        self._check_view(data)
        contact = data.contact
        pb = self._plate_body
        origin = data.xpos[pb]
        rot = data.xmat[pb]
        points, force, torque, zmp = self._sums_core.measure(
            contact.geom,
            contact.frame,
            contact.pos,
            contact.efc_address,
            contact.dim,
            contact.friction,
            data.efc_force,
            origin,
            rot,
            self._model.opt.cone == _PYRAMIDAL,
        )
        self._track(data, points > 0)
        anchor_pos, anchor_rot = self._core.anchor_pos, self._core.anchor_rot
        if anchor_pos is None or anchor_rot is None:
            return points, force, torque, zmp, np.zeros(2), 0.0
        slip = (origin - anchor_pos)[:2]
        yaw = self._sums_core.yaw_about(anchor_rot.ravel(), rot)
        if yaw is None:
            yaw = _yaw_about(anchor_rot[:, 2], anchor_rot, rot.reshape(3, 3))
        return points, force, torque, zmp, slip.copy(), yaw
