"""Independent numpy oracle for the plant tests: URDF kinematics and mass properties.

Parses the URDF with ElementTree and the TOML with tomllib, never through MuJoCo or the
plant's builder, so the plant tests compare MuJoCo's compiled model against a separate
derivation. The tests at the bottom check the oracle itself against the paper (Table IV).
"""

from __future__ import annotations

import math
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

ROBOTS = Path(__file__).resolve().parents[1] / "python" / "rdm" / "data" / "robots"


def rpy_matrix(rpy: np.ndarray) -> np.ndarray:
    """URDF fixed-axis roll-pitch-yaw: R = Rz(yaw) Ry(pitch) Rx(roll)."""
    r, p, y = rpy
    cr, sr, cp, sp, cy, sy = (
        math.cos(r),
        math.sin(r),
        math.cos(p),
        math.sin(p),
        math.cos(y),
        math.sin(y),
    )
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    return rz @ ry @ rx


def axis_angle(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rodrigues rotation matrix."""
    a = axis / np.linalg.norm(axis)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * (k @ k)


def _origin(elem: ET.Element | None) -> tuple[np.ndarray, np.ndarray]:
    if elem is None:
        return np.zeros(3), np.eye(3)
    xyz = np.array([float(v) for v in elem.get("xyz", "0 0 0").split()])
    rpy = np.array([float(v) for v in elem.get("rpy", "0 0 0").split()])
    return xyz, rpy_matrix(rpy)


def robot_files(name: str) -> tuple[Path, Path]:
    """(urdf, toml) of a shipped robot."""
    return ROBOTS / name / f"{name}.urdf", ROBOTS / name / f"{name}.toml"


def link_poses(urdf: Path, q: dict[str, float]) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """World (R, p) of every link with the root link at the identity."""
    root = ET.parse(urdf).getroot()
    joints = root.findall("joint")
    children = {j.find("child").get("link") for j in joints}  # type: ignore[union-attr]
    base = next(l.get("name") for l in root.findall("link") if l.get("name") not in children)
    poses: dict[str, tuple[np.ndarray, np.ndarray]] = {base: (np.eye(3), np.zeros(3))}
    pending = list(joints)
    while pending:
        for j in list(pending):
            parent = j.find("parent").get("link")  # type: ignore[union-attr]
            if parent not in poses:
                continue
            child = j.find("child").get("link")  # type: ignore[union-attr]
            rp, pp = poses[parent]
            xyz, rot = _origin(j.find("origin"))
            r = rp @ rot
            if j.get("type") in ("revolute", "continuous"):
                axis_el = j.find("axis")
                axis = np.array(
                    [
                        float(v)
                        for v in (axis_el.get("xyz") if axis_el is not None else "1 0 0").split()
                    ]
                )
                r = r @ axis_angle(axis, q.get(j.get("name"), 0.0))
            poses[child] = (r, pp + rp @ xyz)
            pending.remove(j)
    return poses


def mass_and_cog(urdf: Path, q: dict[str, float]) -> tuple[float, np.ndarray]:
    """Total mass and centre of gravity (root frame) from the URDF <inertial> tags."""
    poses = link_poses(urdf, q)
    total, moment = 0.0, np.zeros(3)
    for link in ET.parse(urdf).getroot().findall("link"):
        inertial = link.find("inertial")
        if inertial is None:
            continue
        m = float(inertial.find("mass").get("value"))  # type: ignore[union-attr]
        xyz, _ = _origin(inertial.find("origin"))
        r, p = poses[link.get("name")]  # type: ignore[index]
        total += m
        moment += m * (p + r @ xyz)
    return total, moment / total


def rotors(
    toml: Path, urdf: Path, q: dict[str, float]
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(positions, unit axes, spins, drag_to_thrust) of the rotors in the root frame."""
    doc = tomllib.loads(toml.read_text())
    poses = link_poses(urdf, q)
    pos, axes, spin, c = [], [], [], []
    for r in doc["rotors"]:
        rot, p = poses[r["parent"]]
        a = rot @ np.array(r["axis"], dtype=float)
        pos.append(p + rot @ np.array(r["offset"], dtype=float))
        axes.append(a / np.linalg.norm(a))
        spin.append(r["spin"])
        c.append(r["drag_to_thrust"])
    return np.array(pos), np.array(axes), np.array(spin, dtype=float), np.array(c)


def joint_limits(urdf: Path) -> dict[str, tuple[float, float]]:
    """URDF <limit lower upper> per revolute joint."""
    out = {}
    for j in ET.parse(urdf).getroot().findall("joint"):
        lim = j.find("limit")
        if lim is not None:
            out[j.get("name")] = (float(lim.get("lower")), float(lim.get("upper")))  # type: ignore[arg-type]
    return out


# --- the oracle against the paper --------------------------------------------------------------


def test_oracle_total_mass_is_table_iv() -> None:
    """Table IV: 3.35 kg of links plus the 0.35 kg foot module."""
    for name in ("rdm", "rcm"):
        urdf, _ = robot_files(name)
        m, _ = mass_and_cog(urdf, {})
        assert abs(m - (3.35 + 0.35)) < 1e-9


def test_oracle_kinematics_rotation_moves_points() -> None:
    """Bending q1 by 90 deg swings the root-link tip from +x to -z (rotation about +y)."""
    urdf, _ = robot_files("rdm")
    straight = link_poses(urdf, {})["q3_housing"][1]
    bent = link_poses(urdf, {"q1": math.pi / 2})["q3_housing"][1]
    assert np.allclose(straight, [0.4, 0.0, -0.05])
    assert np.allclose(bent, [0.0, 0.0, -0.05 - 0.4], atol=1e-12)
