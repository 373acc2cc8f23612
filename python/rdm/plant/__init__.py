"""MuJoCo plant of the rotor-distributed manipulator (robot-in-the-loop simulation).

One concept per module: :mod:`description` (read URDF + TOML), :mod:`mjcf` (build the
MuJoCo model), :mod:`esc` (duty -> thrust with lag), :mod:`ceiling` (ceiling effect),
:mod:`servo` (servo parameters), :mod:`sensors` (IMU and wrench error models),
:mod:`truth` (ground truth), :mod:`plant` (the :class:`Plant`). See docs/plant.md.
"""

from __future__ import annotations

from rdm.plant.ceiling import CeilingEffect, NoCeilingEffect, ParametricCeilingEffect
from rdm.plant.description import DescriptionError, RobotDescription, load_robot
from rdm.plant.esc import Esc, EscParams
from rdm.plant.mjcf import BuildOptions, ContactParams, build_model, build_spec
from rdm.plant.plant import Plant
from rdm.plant.sensors import ImuNoise, ImuReading, WrenchNoise, WrenchReading
from rdm.plant.servo import ServoParams
from rdm.plant.truth import GroundTruth

__all__ = [
    "BuildOptions",
    "CeilingEffect",
    "ContactParams",
    "DescriptionError",
    "Esc",
    "EscParams",
    "GroundTruth",
    "ImuNoise",
    "ImuReading",
    "NoCeilingEffect",
    "ParametricCeilingEffect",
    "Plant",
    "RobotDescription",
    "ServoParams",
    "WrenchNoise",
    "WrenchReading",
    "build_model",
    "build_spec",
    "load_robot",
]
