"""A Dynamixel servo as a Neuron sees it: configuration, goal handshake and a first-order motion
model (fact sheet sec. 2.4 "Servo target angle", "Servo state", goal-sync handshake).

Positions and currents are raw Dynamixel units (position ticks, current units), exactly the
integers carried on CAN; no unit conversion happens on the Neuron.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Protocol

#: Dynamixel X "Profile Velocity" unit: 0.229 rpm; 4096 ticks per revolution.
TICKS_PER_S_PER_PROFILE_UNIT = 0.229 * 4096.0 / 60.0
#: Dynamixel X default "Moving Threshold" 10 x 0.229 rpm, in ticks/s.
MOVING_THRESHOLD_TICKS_PER_S = 10 * TICKS_PER_S_PER_PROFILE_UNIT
INT16 = (-0x8000, 0x7FFF)


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


class PositionFeed(Protocol):
    """Plant feedback shared by many servos: ``epoch`` changes when the plant moved;
    ``ticks()`` gives every joint's present position in raw ticks at that epoch."""

    epoch: int

    def ticks(self) -> list[float]: ...


def _clip(value: float, low: int, high: int) -> int:
    return int(min(max(round(value), low), high))


class ServoModel:
    """Run-time state of one servo on a Neuron.

    Goal handshake (Neuron side, ``neuronlib/Servo/servo.cpp`` as the fact sheet describes it):
    when torque goes on, the goal is set to the present position and ``send_goal_position``
    is raised; while raised, state reports carry the goal (status bit 2) and goals from CAN are
    ignored unless their ack bit (bit 15) is set, which clears the flag. Goals are also ignored
    while torque is off.
    """

    def __init__(self, config: ServoConfig) -> None:
        #: Bumped by every goal / torque change (a Neuron shares one counter with its servos
        #: and ESC so a plant bridge can skip boards whose outputs did not change).
        self.changes = [0]
        #: Optional plant feedback: ``(feed, joint_index)``; the position is then read from
        #: ``feed.ticks()`` (the plant's angle at the feed's present epoch) when first needed.
        self.feed: tuple[PositionFeed, int] | None = None
        self._feed_epoch = -1
        self._position = float(config.initial_position)
        self.config = config
        self.velocity = 0.0
        self._goal = config.initial_position
        self.goal_current = config.goal_current
        self._torque_enable = False
        self.send_goal_position = False
        self.temperature = config.temperature
        self.hardware_error = 0
        self.homing_offset = 0
        self.round_offset = 0
        #: When set, the plant drives ``current`` (else it follows the position-error model).
        self.external_current: int | None = None

    # ------------------------------------------------------------------ tracked state
    @property
    def position(self) -> float:
        """Present position (raw ticks, float); from the plant feed when one is attached."""
        feed = self.feed
        if feed is not None and feed[0].epoch != self._feed_epoch:
            self._feed_epoch = feed[0].epoch
            position = feed[0].ticks()[feed[1]]
            if not math.isfinite(position):
                raise ValueError(f"present position {position!r} is not finite")
            self._position = position
        return self._position

    @position.setter
    def position(self, value: float) -> None:
        self._position = value
        if self.feed is not None:
            self._feed_epoch = self.feed[0].epoch  # an explicit value holds until the next

    @property
    def goal(self) -> int:
        return self._goal

    @goal.setter
    def goal(self, value: int) -> None:
        if value != self._goal:
            self._goal = value
            self.changes[0] += 1

    @property
    def torque_enable(self) -> bool:
        return self._torque_enable

    @torque_enable.setter
    def torque_enable(self, value: bool) -> None:
        if value != self._torque_enable:
            self._torque_enable = value
            self.changes[0] += 1

    # ------------------------------------------------------------------ commands from CAN
    def set_torque(self, enable: bool) -> None:
        """``setTorque``: a hardware error keeps torque off (Dynamixel shutdown)."""
        enable = enable and self.hardware_error == 0
        if enable and not self.torque_enable:
            self.goal = self.present_position
            self.send_goal_position = True
        self.torque_enable = enable

    def command_goal(self, value: int, ack: bool) -> bool:
        """One goal word from a servo-angle frame; returns True when the goal was applied."""
        if not self.torque_enable:
            return False
        if self.send_goal_position:
            if not ack:
                return False
            self.send_goal_position = False
        self.goal = _clip(value, self.config.min_position, self.config.max_position)
        return True

    def set_homing_offset(self, offset: int) -> None:
        """The reading frame shifts by the offset change (position and goal move together)."""
        delta = offset - self.homing_offset
        self.homing_offset = offset
        self.position += delta
        self.goal += delta

    # ------------------------------------------------------------------ model
    def advance(self, dt: float) -> None:
        """First-order approach to the goal, rate-limited by ``profile_velocity`` if set."""
        if dt <= 0:
            return
        before = self.position
        if self.torque_enable:
            step = (self.goal - self.position) * (1.0 - math.exp(-dt / self.config.time_constant))
            if self.config.profile_velocity > 0:
                vmax = self.config.profile_velocity * TICKS_PER_S_PER_PROFILE_UNIT * dt
                step = max(-vmax, min(vmax, step))
            self.position += step
            if abs(self.goal - self.position) < 0.5:
                self.position = float(self.goal)
        self.velocity = (self.position - before) / dt

    def set_present_position(self, position: float) -> None:
        """Plant feedback: the joint is where the plant says (velocity left to the plant)."""
        if not math.isfinite(position):
            raise ValueError(f"present position {position!r} is not finite")
        self.position = float(position)

    # ------------------------------------------------------------------ readings
    @property
    def present_position(self) -> int:
        return _clip(self.position, *INT16)

    @property
    def moving(self) -> bool:
        return abs(self.velocity) > MOVING_THRESHOLD_TICKS_PER_S

    @property
    def current(self) -> int:
        if self.external_current is not None:
            return self.external_current
        if not self.torque_enable:
            return 0
        limit = self.config.current_limit
        return _clip((self.goal - self.position) * self.config.current_per_tick, -limit, limit)

    @property
    def reported_angle(self) -> int:
        """Angle field of the state frame: the goal while the handshake is pending."""
        return _clip(self.goal, *INT16) if self.send_goal_position else self.present_position

    def reconfigure(self, **changes: object) -> None:
        """Replace configuration fields (board-config sub-commands)."""
        self.config = replace(self.config, **changes)
