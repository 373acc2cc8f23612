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

import hashlib
import math
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

from rdm import _rdm
from rdm._rdm import DescriptionError, ModelError

__all__ = [
    "SHIPPED_ORIGIN",
    "VERTICAL_Q",
    "DescriptionError",
    "ModelError",
    "Robot",
    "RobotSource",
    "robot_source",
    "sha256_text",
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
        file, whose ``urdf`` key names the URDF (relative to the TOML's folder); the files
        are found as :func:`robot_source` finds them."""
        source = robot_source(name_or_path)
        if source.toml_origin.startswith(SHIPPED_ORIGIN):
            return cls.shipped(source.spec)
        return cls.from_files(source.urdf_origin, source.toml_origin)

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


#: How a :class:`RobotSource` names a file of a shipped description (``shipped:rdm/rdm.urdf``).
SHIPPED_ORIGIN = "shipped:"


def sha256_text(text: str) -> str:
    """Hex SHA-256 of ``text`` encoded as UTF-8 (how a recording names a file's content)."""
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


@dataclass(frozen=True)
class RobotSource:
    """A robot description's two files as text and where they were read: what a flight
    recording stores so that a replay builds the same robot after the files moved."""

    #: as given: a shipped name (``rdm``, ``rcm``) or the path of a description's TOML
    spec: str
    urdf: str
    toml: str
    #: ``shipped:<name>/<file>`` or the absolute path each text was read from
    urdf_origin: str
    toml_origin: str

    def robot(self) -> _rdm.Robot:
        """The robot these texts describe (errors name the origin and field)."""
        return _rdm.Robot.from_strs(self.urdf, self.toml, self.urdf_origin, self.toml_origin)


def robot_source(spec: str | Path) -> RobotSource:
    """Read a robot description: a shipped name, or the path of its TOML file, whose ``urdf``
    key names the URDF (relative to the TOML's folder). DescriptionError names the robot and
    the missing file or key."""
    import tomllib

    spec = str(spec)
    if Path(spec).suffix != ".toml":
        with shipped_robot_files(spec) as (urdf, toml):
            return RobotSource(
                spec,
                urdf.read_text(encoding="utf-8"),
                toml.read_text(encoding="utf-8"),
                f"{SHIPPED_ORIGIN}{spec}/{urdf.name}",
                f"{SHIPPED_ORIGIN}{spec}/{toml.name}",
            )
    toml_path = Path(spec).absolute()
    if not toml_path.is_file():
        raise DescriptionError(f"--robot {spec}: no file {toml_path}")
    try:
        toml_text = toml_path.read_text(encoding="utf-8")
        urdf_name = tomllib.loads(toml_text).get("urdf")
    except (OSError, UnicodeDecodeError) as exc:
        raise DescriptionError(f"--robot {spec}: {exc}") from None
    except tomllib.TOMLDecodeError as exc:
        raise DescriptionError(f"{toml_path}: not valid TOML: {exc}") from None
    if not isinstance(urdf_name, str) or not urdf_name:
        raise DescriptionError(f"{toml_path}: urdf: missing (the URDF file next to the TOML)")
    urdf_path = toml_path.parent / urdf_name
    if not urdf_path.is_file():
        raise DescriptionError(f"{toml_path}: urdf: no file {urdf_path}")
    try:
        urdf_text = urdf_path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise DescriptionError(f"--robot {spec}: {exc}") from None
    return RobotSource(spec, urdf_text, toml_text, str(urdf_path), str(toml_path))
