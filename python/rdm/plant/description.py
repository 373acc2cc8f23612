"""Read a robot description (URDF + TOML) into plain dataclasses for the plant builder.

The plant is generated from the same two files the core loads, so the simulated robot and
the controller's model never drift apart. This reader is deliberately independent of the
Rust model (``rdm._rdm.Robot``): it needs only :mod:`tomllib` and the URDF path.
"""

from __future__ import annotations

import math
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


#: Physical bounds on the TOML's numbers, the same as the core loader's
#: (``rdm_core::model::bounds``): rule name -> (largest magnitude, unit). A finite number
#: past them (an offset of 1e308 m) overflows the products built from it. ASSUMPTION
#: (docs/model.md).
BOUNDS: dict[str, tuple[float, str]] = {
    "length": (1e3, " m"),
    "axis component": (1e3, ""),
    "force": (1e5, " N"),
    "torque": (1e5, " N m"),
    "friction coefficient": (1e2, ""),
}


def _num(value: object, field: str, rule: str) -> float:
    """``value`` as a finite float within the bound ``rule`` of :data:`BOUNDS`."""
    try:
        x = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise DescriptionError(f"{field}: expected a number, got {value!r}") from None
    if not math.isfinite(x):
        raise DescriptionError(f"{field}: NaN or infinite value")
    limit, unit = BOUNDS[rule]
    if abs(x) > limit:
        raise DescriptionError(f"{field}: {x:g} is outside the {rule} bound |x| <= {limit:g}{unit}")
    return x


def _vec3(value: object, field: str, rule: str) -> tuple[float, float, float]:
    if not isinstance(value, list) or len(value) != 3:
        raise DescriptionError(f"{field}: expected a list of 3 numbers, got {value!r}")
    return (_num(value[0], field, rule), _num(value[1], field, rule), _num(value[2], field, rule))


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
    if not isinstance(size, list) or len(size) != 2:
        raise DescriptionError(f"foot.plate_size: expected a list of 2 numbers, got {size!r}")
    rotors = []
    for i, r in enumerate(_get(doc, "rotors", "toml")):  # type: ignore[union-attr]
        field = f"rotors[{i}]"
        spin = int(_get(r, "spin", field))
        if spin not in (-1, 1):
            raise DescriptionError(f"{field}.spin: must be +1 or -1, got {spin}")
        tmin = _num(_get(r, "thrust_min", field), f"{field}.thrust_min", "force")
        tmax = _num(_get(r, "thrust_max", field), f"{field}.thrust_max", "force")
        if not 0.0 <= tmin < tmax:
            raise DescriptionError(f"{field}.thrust_min/max: need 0 <= min < max")
        rotors.append(
            RotorSpec(
                name=str(_get(r, "name", field)),
                parent=str(_get(r, "parent", field)),
                offset=_vec3(_get(r, "offset", field), f"{field}.offset", "length"),
                axis=_vec3(_get(r, "axis", field), f"{field}.axis", "axis component"),
                spin=spin,
                drag_to_thrust=_num(
                    _get(r, "drag_to_thrust", field), f"{field}.drag_to_thrust", "length"
                ),
                thrust_min=tmin,
                thrust_max=tmax,
                diameter=_num(_get(r, "diameter", field), f"{field}.diameter", "length"),
            )
        )
    joints = []
    for i, j in enumerate(_get(doc, "joints", "toml")):  # type: ignore[union-attr]
        field = f"joints[{i}]"
        stall = _num(_get(j, "stall_torque", field), f"{field}.stall_torque", "torque")
        if stall <= 0.0:
            raise DescriptionError(f"{field}.stall_torque: must be > 0")
        joints.append(JointSpec(str(_get(j, "name", field)), str(j.get("servo", "")), stall))
    sensors = {}
    for key, s in dict(doc.get("sensors", {})).items():
        sensors[key] = WrenchSensorSpec(
            name=key,
            frame=str(_get(s, "frame", f"sensors.{key}")),
            model=str(s.get("model", "")),
            force_range=_vec3(
                _get(s, "force_range", f"sensors.{key}"), f"sensors.{key}.force_range", "force"
            ),
            torque_range=_vec3(
                _get(s, "torque_range", f"sensors.{key}"), f"sensors.{key}.torque_range", "torque"
            ),
        )
    return RobotDescription(
        name=str(_get(doc, "name", "toml")),
        urdf_path=urdf_path,
        toml_path=toml_path,
        joint_order=tuple(str(n) for n in _get(doc, "joint_order", "toml")),  # type: ignore[union-attr]
        foot_frame=str(_get(frames, "foot", "frames")),
        end_effector_frame=str(_get(frames, "end_effector", "frames")),
        foot_plate_size=(
            _num(size[0], "foot.plate_size", "length"),
            _num(size[1], "foot.plate_size", "length"),
        ),
        friction_xy=_num(
            _get(foot, "friction_xy", "foot"), "foot.friction_xy", "friction coefficient"
        ),
        friction_z=_num(
            _get(foot, "friction_z", "foot"), "foot.friction_z", "friction coefficient"
        ),
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
