"""Collision shapes approximating the robot (eq. 67): capsules for the three main links,
a sphere around each dual-rotor unit (both rotors and their guards). ASSUMPTIONS: sizes
from the description generator's parts list (link radii, rotor spacing and diameter)."""

from __future__ import annotations

from rdm import descriptions as d

#: (name, link, kind, a, b, radius); a sphere uses ``a`` as its centre.
_SHAPES = (
    ("root_link", "root_link", "capsule", (0.0, 0.0, 0.0), (d.ROOT_LINK_LENGTH, 0.0, 0.0),
     d.ROOT_LINK_RADIUS),
    ("middle_link", "middle_link", "capsule", (0.0, 0.0, 0.0), (d.MIDDLE_LINK_LENGTH, 0.0, 0.0),
     d.MIDDLE_LINK_RADIUS),
    ("end_link", "end_link", "capsule", (0.0, 0.0, 0.0), (d.END_LINK_LENGTH, 0.0, 0.0),
     d.END_LINK_RADIUS),
    ("foot_unit", "foot_unit_pitch", "sphere", (0.0, 0.0, d.ROTOR_HEIGHT), (0.0, 0.0, 0.0),
     d.ROTOR_SPACING / 2 + d.ROTOR_DIAMETER / 2),
    ("arm_unit", "arm_unit_pitch", "sphere", (0.0, 0.0, d.ROTOR_HEIGHT), (0.0, 0.0, 0.0),
     d.ROTOR_SPACING / 2 + d.ROTOR_DIAMETER / 2),
)  # fmt: skip

#: Pairs that must not touch. Adjacent parts (sharing a joint) are left out: their
#: clearance is zero by construction. The two unit spheres are not paired with each other:
#: a sphere around a flat rotor pair is far too conservative there (Table II's middle
#: variant has its units 0.20 m apart, less than the spheres' 0.267 m, in every pose), and
#: eq. (68) already keeps every rotor of one unit a diameter away from those of the other.
#: ``None`` as the second name: the ceiling plane.
_PAIRS = (
    ("root_link", "end_link"),
    ("foot_unit", "end_link"),
    ("arm_unit", "root_link"),
    ("middle_link", None),
    ("end_link", None),
)


def collision_config(link_names: list[str], unit_parents: dict[str, str]) -> dict[str, list]:
    """Shapes and pairs for a robot with these URDF link names. ``unit_parents`` maps a
    unit sphere name to the link its unit is mounted on; pairs between parts mounted on the
    same link are dropped (their distance cannot change)."""
    shapes, index, mount = [], {}, {}
    for name, link, kind, a, b, r in _SHAPES:
        if link not in link_names:
            continue
        index[name] = len(shapes)
        mount[name] = unit_parents.get(name, link)
        shapes.append((kind, link_names.index(link), a, b, r))
    pairs = []
    for a, b in _PAIRS:
        if a not in index or (b is not None and b not in index):
            continue
        if b is None:
            pairs.append((index[a], -1))
        elif mount[a] != mount[b]:
            pairs.append((index[a], index[b]))
    return {"shapes": shapes, "pairs": pairs}
