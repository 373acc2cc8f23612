"""Servo model parameters: Dynamixel-style position servos as MuJoCo position actuators.

Each joint gets a ``general`` actuator with torque ``kp (target - q) - kv qdot`` limited to
the stall torque (``forcerange``), plus a joint armature for the reflected motor inertia.
With a light load the step response is first-order with time constant ``kv / kp``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

# ASSUMPTION: datasheet stall currents at 12 V, used only to turn torque into a current
# reading (a linear torque constant stall_torque / stall_current).
STALL_CURRENT_A: dict[str, float] = {"XH430-W350-R": 2.3, "XL430-W250-T": 1.4}
DEFAULT_STALL_CURRENT_A = 2.0


@dataclass(frozen=True)
class ServoParams:
    """Position-servo gains shared by all joints (ASSUMPTIONS, see docs/plant.md).

    kp 30 N m/rad and kv 1.5 N m s/rad give tau = kv/kp = 0.05 s; armature 0.01 kg m^2 is
    the order of a 350:1 geared coreless motor's reflected inertia.
    """

    kp: float = 30.0
    kv: float = 1.5
    armature: float = 0.01
    frictionloss: float = 0.0
    #: Time constant [s] of the servo's goal smoothing: the position loop follows the goal
    #: through a first-order filter (MuJoCo ``filterexact`` actuator dynamics), standing for
    #: the Dynamixel profile generator that ramps each Goal Position written instead of stepping to
    #: it (Profile Acceleration / Profile Velocity). 0 (default): no smoothing, the goal is
    #: the loop's reference at once (Profile Velocity 0, "infinite", the factory value).
    goal_filter_s: float = 0.0

    def __post_init__(self) -> None:
        if not (self.kp > 0 and self.kv >= 0 and self.armature >= 0 and self.frictionloss >= 0):
            raise ValueError("ServoParams: kp > 0 and kv, armature, frictionloss >= 0 required")
        if not (math.isfinite(self.goal_filter_s) and self.goal_filter_s >= 0):
            raise ValueError(
                f"ServoParams: goal_filter_s {self.goal_filter_s!r} must be finite and >= 0"
            )

    @property
    def time_constant(self) -> float:
        """First-order time constant kv/kp [s] of an unloaded joint."""
        return self.kv / self.kp


def torque_constant(servo_model: str, stall_torque: float) -> float:
    """Linear torque constant [N m / A] of a servo model (ASSUMPTION: stall values)."""
    return stall_torque / STALL_CURRENT_A.get(servo_model, DEFAULT_STALL_CURRENT_A)
