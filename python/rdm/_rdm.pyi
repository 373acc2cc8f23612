"""Type stubs of the compiled core :mod:`rdm._rdm` (see crates/rdm_py)."""

__version__: str

class RdmError(ValueError):
    """Base class of every error raised by rdm's core."""

# --- model ---
from os import PathLike  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402
import numpy.typing as npt  # noqa: E402

_F = npt.NDArray[np.float64]
_Pose = _F | list[list[float]] | list[float] | None

class DescriptionError(RdmError):
    """A robot description is malformed or inconsistent; the message names file and field."""

class ModelError(RdmError):
    """Bad input to a model evaluation; the message names the argument."""

class Robot:
    """Robot description (URDF + TOML) with its evaluation workspace.

    Joint order of ``q``: the TOML's ``joint_order`` (shipped robots:
    q1..q6, alpha1, beta1, alpha2, beta2). ``base_pose`` is the pose of the root link (the
    foot) in the world: None (identity), a 4x4 matrix or [x, y, z, roll, pitch, yaw]
    (R = Rz(yaw) Ry(pitch) Rx(roll)).
    """

    def __init__(self, urdf: str | PathLike[str], toml: str | PathLike[str]) -> None: ...
    @staticmethod
    def from_strs(
        urdf_text: str, toml_text: str, urdf_name: str = "<urdf>", toml_name: str = "<toml>"
    ) -> Robot: ...
    @property
    def name(self) -> str: ...
    @property
    def sources(self) -> tuple[str, str]: ...
    @property
    def joint_names(self) -> list[str]: ...
    @property
    def n_q(self) -> int: ...
    @property
    def n_rotors(self) -> int: ...
    @property
    def mass(self) -> float: ...
    @property
    def joint_limits(self) -> _F:
        """(n_q, 2) lower/upper position limits [rad]."""
    @property
    def stall_torques(self) -> _F: ...
    @property
    def link_names(self) -> list[str]: ...
    @property
    def rotor_names(self) -> list[str]: ...
    @property
    def frame_names(self) -> list[str]: ...
    @property
    def rotors(self) -> list[dict[str, Any]]:
        """name, parent, offset, axis, spin, drag_to_thrust, thrust_min, thrust_max, diameter."""
    @property
    def vectoring_units(self) -> list[dict[str, Any]]: ...
    @property
    def plate_size(self) -> tuple[float, float]: ...
    @property
    def friction(self) -> tuple[float, float]: ...
    @property
    def sensors(self) -> dict[str, dict[str, Any]]: ...
    def evaluate(self, q: npt.ArrayLike, base_pose: _Pose = None) -> dict[str, Any]:
        """Keys: mass, cog (world), inertia (about CoG, CoG frame), inertia_world,
        allocation (6 x N, CoG frame, eqs. 7-9), allocation_bar (4 x N), rotor_positions
        (N x 3), rotor_directions (N x 3), frames (name -> 4x4 world pose), foot_in_cog
        (4x4), unit_parent_rotations (list of 3x3, C<-L_i), aerial_zmp (2,), zmp_margin,
        zmp_inside, zmp_degenerate, rho (eq. 65)."""
    def aerial_zmp_from_thrusts(
        self, q: npt.ArrayLike, thrusts: npt.ArrayLike, base_pose: _Pose = None
    ) -> dict[str, Any] | None: ...
    def static_torques(
        self,
        q: npt.ArrayLike,
        thrusts: npt.ArrayLike,
        base_pose: _Pose = None,
        foot_wrench: npt.ArrayLike | None = None,
        end_effector_wrench: npt.ArrayLike | None = None,
        gravity: tuple[float, float, float] = (0.0, 0.0, -9.80665),
    ) -> tuple[_F, _F]:
        """(tau of eq. 61 in q order, net external wrench about the base origin)."""
    def jacobian(self, frame: str, zeta: npt.ArrayLike) -> _F:
        """6 x (6 + n_q) w.r.t. zeta = [p, roll, pitch, yaw, q]; rows: world linear, angular."""
    def stability_gradient(self, q: npt.ArrayLike) -> _F: ...
