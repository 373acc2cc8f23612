"""The shipped robot's joint limits, read from its URDF with ElementTree (an oracle
independent of the description loader the onboard node uses)."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import rdm


def urdf_limits() -> dict[str, tuple[float, float]]:
    """(lower, upper) of every limited joint of the shipped rdm URDF."""
    urdf = Path(rdm.__file__).parent / "data" / "robots" / "rdm" / "rdm.urdf"
    out = {}
    for j in ET.parse(urdf).getroot().iter("joint"):
        limit = j.find("limit")
        if limit is not None:
            out[j.get("name")] = (float(limit.get("lower")), float(limit.get("upper")))
    return out
