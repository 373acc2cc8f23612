"""The robot model: Python face of ``rdm_core::model`` (kinematics, mass properties, rotor
allocation Q(q), aerial ZMP, static joint torques, Jacobians, stability measure).

>>> from rdm.model import Robot
>>> robot = Robot.default()            # the shipped RDM (rdm/data/robots/rdm)
>>> out = robot.evaluate([0.0] * robot.n_q)
>>> out["mass"], out["allocation"].shape
(3.7, (6, 4))

Joint order everywhere: ``q = [q1, q2, q3, q4, q5, q6, alpha1, beta1, alpha2, beta2]``.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from contextlib import contextmanager
from importlib import resources
from pathlib import Path

from rdm import _rdm
from rdm._rdm import DescriptionError, ModelError

__all__ = [
    "VERTICAL_Q",
    "DescriptionError",
    "ModelError",
    "Robot",
    "shipped_robot_files",
]

#: Straight vertical flight configuration of the shipped RDM (foot on top, arm hanging
#: straight down, both units turned so the thrust points up, the arm unit's rotor pair
#: turned 90 deg about the arm so the four rotors span a rhombus): q1 = +90 deg points the
#: root link along -z of the foot frame, beta = -90 deg turns each unit's thrust from the
#: link's z axis to -x (up), alpha2 = 90 deg turns the arm pair.
VERTICAL_Q: tuple[float, ...] = (
    math.pi / 2, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, -math.pi / 2, math.pi / 2, -math.pi / 2
)  # fmt: skip


@contextmanager
def shipped_robot_files(name: str) -> Iterator[tuple[Path, Path]]:
    """Paths of a shipped description's URDF and TOML (``name``: ``"rdm"`` or ``"rcm"``)."""
    root = resources.files("rdm") / "data" / "robots" / name
    with (
        resources.as_file(root / f"{name}.urdf") as urdf,
        resources.as_file(root / f"{name}.toml") as toml,
    ):
        if not Path(urdf).is_file():
            raise DescriptionError(f"no shipped robot description named {name!r}")
        yield Path(urdf), Path(toml)


class Robot(_rdm.Robot):
    """A robot description with its evaluation workspace (see ``rdm._rdm.Robot``)."""

    @classmethod
    def from_files(cls, urdf: str | Path, toml: str | Path) -> Robot:
        """Load from a URDF file and a TOML file; errors name the file and field."""
        return cls(Path(urdf), Path(toml))

    @classmethod
    def shipped(cls, name: str) -> Robot:
        """A description shipped in the wheel under ``rdm/data/robots/<name>``."""
        with shipped_robot_files(name) as (urdf, toml):
            return cls(urdf, toml)

    @classmethod
    def load(cls, name_or_path: str | Path) -> Robot:
        """A shipped robot by name (``rdm``, ``rcm``), or any robot by the path of its TOML
        file, whose ``urdf`` key names the URDF (relative to the TOML's folder)."""
        p = Path(name_or_path)
        if p.suffix != ".toml":
            return cls.shipped(str(name_or_path))
        import tomllib

        try:
            with open(p, "rb") as f:
                urdf = tomllib.load(f).get("urdf")
        except OSError as exc:
            raise DescriptionError(f"{p}: {exc.strerror or exc}") from None
        except tomllib.TOMLDecodeError as exc:
            raise DescriptionError(f"{p}: not valid TOML: {exc}") from None
        if not isinstance(urdf, str) or not urdf:
            raise DescriptionError(f"{p}: urdf: missing (the URDF file next to the TOML)")
        return cls.from_files(p.parent / urdf, p)

    @classmethod
    def default(cls) -> Robot:
        """The paper's RDM (arm vectoring apparatus at the end of the middle link)."""
        return cls.shipped("rdm")

    @classmethod
    def rcm(cls) -> Robot:
        """The rotor-concentrated comparison robot (all four rotors at the root link)."""
        return cls.shipped("rcm")

    @staticmethod
    def variant(layout: str = "rdm", arm_unit_position: float = 1.0) -> _rdm.Robot:
        """A generated description, e.g. Table II's arm-unit positions 0 / 0.5 / 1.

        Returns the core class (``rdm._rdm.Robot``): every evaluation method is there.
        """
        from rdm.descriptions import build_description

        desc = build_description(layout, arm_unit_position)
        return _rdm.Robot.from_strs(desc.urdf, desc.toml, f"{desc.name}.urdf", f"{desc.name}.toml")
