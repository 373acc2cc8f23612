"""Read a robot description (URDF + TOML) into plain dataclasses for the plant builder.

The plant is generated from the same two files the core loads, so the simulated robot and
the controller's model never drift apart. This reader is deliberately independent of the
Rust model (``rdm._rdm.Robot``): it needs only :mod:`tomllib` and the URDF path.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - exercised on 3.10 only
    import tomli as tomllib

ROBOTS_DIR = Path(__file__).resolve().parents[1] / "data" / "robots"


class DescriptionError(ValueError):
    """A description file is missing a field or holds an invalid value (message names it)."""


@dataclass(frozen=True)
class RotorSpec:
    """One rotor: thrust along ``axis`` of link ``parent`` at ``offset`` (parent frame)."""

    name: str
    parent: str
    offset: tuple[float, float, float]
    axis: tuple[float, float, float]
    spin: int  # sigma_i of eq. (9)
    drag_to_thrust: float  # c of eq. (9) [m]
    thrust_min: float
    thrust_max: float
    diameter: float

    @property
    def radius(self) -> float:
        """Propeller radius R [m]."""
        return 0.5 * self.diameter


@dataclass(frozen=True)
class JointSpec:
    """A servo-driven joint: name, servo model and stall torque [N m]."""

    name: str
    servo: str
    stall_torque: float


@dataclass(frozen=True)
class WrenchSensorSpec:
    """A 6-axis force/torque sensor: frame (URDF link), model and rated capacities."""

    name: str
    frame: str
    model: str
    force_range: tuple[float, float, float]
    torque_range: tuple[float, float, float]


@dataclass(frozen=True)
class RobotDescription:
    """Everything the plant needs from ``<robot>.toml`` plus the URDF path."""

    name: str
    urdf_path: Path
    toml_path: Path
    joint_order: tuple[str, ...]
    foot_frame: str
    end_effector_frame: str
    foot_plate_size: tuple[float, float]
    friction_xy: float
    friction_z: float
    rotors: tuple[RotorSpec, ...]
    joints: tuple[JointSpec, ...]
    wrench_sensors: dict[str, WrenchSensorSpec]

    def joint(self, name: str) -> JointSpec:
        """The joint spec called ``name`` (DescriptionError if absent)."""
        for j in self.joints:
            if j.name == name:
                return j
        raise DescriptionError(f"joints: no joint named {name!r}")


def _vec3(value: object, field: str) -> tuple[float, float, float]:
    if not isinstance(value, list) or len(value) != 3:
        raise DescriptionError(f"{field}: expected a list of 3 numbers, got {value!r}")
    return (float(value[0]), float(value[1]), float(value[2]))


def _get(table: dict, key: str, field: str) -> object:
    if key not in table:
        raise DescriptionError(f"{field}.{key}: missing")
    return table[key]


def load_description(toml_path: str | Path) -> RobotDescription:
    """Load a robot from its TOML file; the URDF is resolved relative to it."""
    toml_path = Path(toml_path)
    if not toml_path.is_file():
        raise DescriptionError(f"toml_path: no such file {toml_path}")
    with toml_path.open("rb") as f:
        doc = tomllib.load(f)
    urdf_path = toml_path.parent / str(_get(doc, "urdf", "toml"))
    if not urdf_path.is_file():
        raise DescriptionError(f"urdf: no such file {urdf_path}")
    frames = _get(doc, "frames", "toml")
    foot = _get(doc, "foot", "toml")
    size = _get(foot, "plate_size", "foot")
    rotors = []
    for i, r in enumerate(_get(doc, "rotors", "toml")):  # type: ignore[union-attr]
        field = f"rotors[{i}]"
        spin = int(_get(r, "spin", field))
        if spin not in (-1, 1):
            raise DescriptionError(f"{field}.spin: must be +1 or -1, got {spin}")
        tmin, tmax = float(_get(r, "thrust_min", field)), float(_get(r, "thrust_max", field))
        if not 0.0 <= tmin < tmax:
            raise DescriptionError(f"{field}.thrust_min/max: need 0 <= min < max")
        rotors.append(
            RotorSpec(
                name=str(_get(r, "name", field)),
                parent=str(_get(r, "parent", field)),
                offset=_vec3(_get(r, "offset", field), f"{field}.offset"),
                axis=_vec3(_get(r, "axis", field), f"{field}.axis"),
                spin=spin,
                drag_to_thrust=float(_get(r, "drag_to_thrust", field)),
                thrust_min=tmin,
                thrust_max=tmax,
                diameter=float(_get(r, "diameter", field)),
            )
        )
    joints = []
    for i, j in enumerate(_get(doc, "joints", "toml")):  # type: ignore[union-attr]
        field = f"joints[{i}]"
        stall = float(_get(j, "stall_torque", field))
        if stall <= 0.0:
            raise DescriptionError(f"{field}.stall_torque: must be > 0")
        joints.append(JointSpec(str(_get(j, "name", field)), str(j.get("servo", "")), stall))
    sensors = {}
    for key, s in dict(doc.get("sensors", {})).items():
        sensors[key] = WrenchSensorSpec(
            name=key,
            frame=str(_get(s, "frame", f"sensors.{key}")),
            model=str(s.get("model", "")),
            force_range=_vec3(_get(s, "force_range", f"sensors.{key}"), f"{key}.force_range"),
            torque_range=_vec3(_get(s, "torque_range", f"sensors.{key}"), f"{key}.torque_range"),
        )
    return RobotDescription(
        name=str(_get(doc, "name", "toml")),
        urdf_path=urdf_path,
        toml_path=toml_path,
        joint_order=tuple(str(n) for n in _get(doc, "joint_order", "toml")),  # type: ignore[union-attr]
        foot_frame=str(_get(frames, "foot", "frames")),
        end_effector_frame=str(_get(frames, "end_effector", "frames")),
        foot_plate_size=(float(size[0]), float(size[1])),  # type: ignore[index]
        friction_xy=float(_get(foot, "friction_xy", "foot")),
        friction_z=float(_get(foot, "friction_z", "foot")),
        rotors=tuple(rotors),
        joints=tuple(joints),
        wrench_sensors=sensors,
    )


def robot_toml(name: str) -> Path:
    """Path of a shipped robot's TOML (``rdm`` or ``rcm``)."""
    path = ROBOTS_DIR / name / f"{name}.toml"
    if not path.is_file():
        known = sorted(p.name for p in ROBOTS_DIR.iterdir() if p.is_dir())
        raise DescriptionError(f"robot: unknown robot {name!r} (shipped: {known})")
    return path


def load_robot(name_or_path: str | Path) -> RobotDescription:
    """Load a shipped robot by name, or any robot by the path of its TOML file."""
    p = Path(name_or_path)
    if p.suffix == ".toml":
        return load_description(p)
    return load_description(robot_toml(str(name_or_path)))
