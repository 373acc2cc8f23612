"""A Dynamixel servo as a Neuron sees it: its configuration (fact sheet sec. 2.4 "Servo target
angle", "Servo state"). The goal handshake and the first-order motion model run in the Neuron
core (``rdm_core::firmware::neuron``).

Positions and currents are raw Dynamixel units (position ticks, current units), exactly the
integers carried on CAN; no unit conversion happens on the Neuron.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

#: Dynamixel X "Profile Velocity" unit: 0.229 rpm; 4096 ticks per revolution.
TICKS_PER_S_PER_PROFILE_UNIT = 0.229 * 4096.0 / 60.0
#: Dynamixel X default "Moving Threshold" 10 x 0.229 rpm, in ticks/s.
MOVING_THRESHOLD_TICKS_PER_S = 10 * TICKS_PER_S_PER_PROFILE_UNIT


@dataclass(frozen=True)
class ServoConfig:
    """One servo behind a Neuron (what INITIAL_CONFIG_1/2/3 report) plus model parameters.

    ``send_data_flag`` False marks a "gimbal" servo: it reports no state on CAN and counts for
    the robot-model inference (fact sheet sec. 2.7). Defaults are Dynamixel XM430 factory values
    where one exists (P 800, current limit 1193, position limits 0..4095); ``time_constant`` and
    ``current_per_tick`` are model assumptions (see docs/canbus.md).
    """

    dynamixel_id: int = 1
    send_data_flag: bool = True
    external_encoder_flag: bool = False
    p_gain: int = 800
    i_gain: int = 0
    d_gain: int = 0
    #: 0 = no velocity limit (Dynamixel semantics), else 0.229 rpm units.
    profile_velocity: int = 0
    current_limit: int = 1193
    goal_current: int = 0
    joint_resolution: int = 4096
    servo_resolution: int = 4096
    min_position: int = 0
    max_position: int = 4095
    initial_position: int = 2048
    temperature: int = 35
    #: First-order lag of the position toward the goal, seconds.
    time_constant: float = 0.05
    #: Reported current per tick of position error while torque is on (clipped to the limit).
    current_per_tick: float = 2.0

    def __post_init__(self) -> None:
        if not self.min_position <= self.initial_position <= self.max_position:
            raise ValueError(
                f"ServoConfig: initial_position {self.initial_position} outside "
                f"[{self.min_position}, {self.max_position}]"
            )
        if not (math.isfinite(self.time_constant) and self.time_constant > 0):
            raise ValueError(f"ServoConfig: time_constant {self.time_constant!r} must be > 0")
        if not 0 <= self.dynamixel_id <= 252:
            raise ValueError(f"ServoConfig: dynamixel_id {self.dynamixel_id} not in 0..252")
