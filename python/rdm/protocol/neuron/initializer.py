"""INITIALIZER (device 7) frames: enumeration, INITIAL_CONFIG request/0..3 and every
BOARD_CONFIG_REQUEST sub-command (fact sheet sec. 2.3, 2.4, 2.5).

Payload lengths of the board-config sub-commands follow Spinal's ``CANInitializer::configDevice``:
DLC = 1 (sub-command byte) + the bytes listed in the fact sheet's table.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import ClassVar

from .base import NeuronFrame, StructFrame, check_dlc
from .ids import BROADCAST_ID, MAX_SERVO_NUM, Device, Direction, InitializerMessage, check_slave

_INDEX = (0, MAX_SERVO_NUM - 1)


class BoardConfigCommand(enum.IntEnum):
    """Sub-command byte of BOARD_CONFIG_REQUEST (= ``SetBoardConfig.srv`` command numbers)."""

    SET_SLAVE_ID = 0
    SET_IMU_SEND_FLAG = 1
    SET_SERVO_HOMING_OFFSET = 2
    SET_SERVO_PID_GAIN = 3
    SET_SERVO_PROFILE_VEL = 4
    SET_SEND_DATA_FLAG = 5
    SET_SERVO_CURRENT_LIMIT = 6
    REBOOT = 7
    SET_DYNAMIXEL_TTL_RS485_MIXED = 8
    SET_EXTERNAL_ENCODER_FLAG = 9
    SET_RESOLUTION_RATIO = 10
    SET_SERVO_ROUND_OFFSET = 11
    SET_SERVO_PULLEY_SKIP_THRESH = 12


class _Initializer:
    DEVICE: ClassVar[int] = Device.INITIALIZER


# ---------------------------------------------------------------- enumeration / config request


@dataclass(frozen=True)
class EnumRequest(_Initializer, NeuronFrame):
    """S->N broadcast (slave 15), DLC 0: every Neuron answers with an EnumResponse."""

    KIND: ClassVar[str] = "enum_request"
    DIRECTION: ClassVar[Direction] = Direction.SPINAL_TO_NEURON
    MESSAGE: ClassVar[int] = InitializerMessage.ENUM

    def _slave_field(self) -> int:
        return BROADCAST_ID

    def encode(self) -> bytes:
        return b""

    @classmethod
    def decode_payload(cls, data: bytes) -> EnumRequest:
        check_dlc(cls.KIND, data, (0,))
        return cls()


@dataclass(frozen=True)
class _EmptyAddressed(_Initializer, NeuronFrame):
    slave: int

    def __post_init__(self) -> None:
        check_slave(self.slave)

    def encode(self) -> bytes:
        return b""

    @classmethod
    def decode_payload(cls, slave: int, data: bytes) -> _EmptyAddressed:
        check_dlc(cls.KIND, data, (0,))
        return cls(slave)


@dataclass(frozen=True)
class EnumResponse(_EmptyAddressed):
    """N->S, DLC 0, slave field = the responding Neuron's id."""

    KIND: ClassVar[str] = "enum_response"
    DIRECTION: ClassVar[Direction] = Direction.NEURON_TO_SPINAL
    MESSAGE: ClassVar[int] = InitializerMessage.ENUM


@dataclass(frozen=True)
class InitialConfigRequest(_EmptyAddressed):
    """S->N to one Neuron, DLC 0: the Neuron replies with INITIAL_CONFIG_0 then 1/2/3 per servo."""

    KIND: ClassVar[str] = "initial_config_request"
    DIRECTION: ClassVar[Direction] = Direction.SPINAL_TO_NEURON
    MESSAGE: ClassVar[int] = InitializerMessage.CONFIG_0


# ---------------------------------------------------------------- INITIAL_CONFIG_0..3 (N->S)


class _Reply(_Initializer):
    DIRECTION: ClassVar[Direction] = Direction.NEURON_TO_SPINAL


@dataclass(frozen=True)
class InitialConfig0(_Reply, StructFrame):
    """``[servo_num, imu_send_flag, ttl_rs485_mixed, pulley_skip_thresh(u16)]``, DLC 5."""

    slave: int
    servo_num: int
    imu_send_flag: bool
    ttl_rs485_mixed: bool
    pulley_skip_thresh: int

    KIND: ClassVar[str] = "initial_config_0"
    MESSAGE: ClassVar[int] = InitializerMessage.CONFIG_0
    CODES: ClassVar[str] = "B??H"
    LIMITS: ClassVar[dict[str, tuple[int, int]]] = {"servo_num": (0, MAX_SERVO_NUM)}


@dataclass(frozen=True)
class InitialConfig1(_Reply, StructFrame):
    """``[index, dynamixel_id, p_gain, i_gain, d_gain]`` (gains u16), DLC 8, one per servo."""

    slave: int
    index: int
    dynamixel_id: int
    p_gain: int
    i_gain: int
    d_gain: int

    KIND: ClassVar[str] = "initial_config_1"
    MESSAGE: ClassVar[int] = InitializerMessage.CONFIG_1
    CODES: ClassVar[str] = "BBHHH"
    LIMITS: ClassVar[dict[str, tuple[int, int]]] = {"index": _INDEX}


@dataclass(frozen=True)
class InitialConfig2(_Reply, StructFrame):
    """``[index, present_position(i16), profile_velocity(u16), current_limit(u16), flags]``.

    ``flags`` bit0 = send_data_flag, bit1 = external_encoder_flag; other bits must be 0.
    """

    slave: int
    index: int
    present_position: int
    profile_velocity: int
    current_limit: int
    send_data_flag: bool
    external_encoder_flag: bool

    KIND: ClassVar[str] = "initial_config_2"
    MESSAGE: ClassVar[int] = InitializerMessage.CONFIG_2
    CODES: ClassVar[str] = "BhHH??"  # the two bools share the last byte, see encode()
    LIMITS: ClassVar[dict[str, tuple[int, int]]] = {"index": _INDEX}

    @classmethod
    def dlc(cls) -> int:
        return 8

    def encode(self) -> bytes:
        import struct

        flags = int(self.send_data_flag) | int(self.external_encoder_flag) << 1
        return struct.pack(
            "<BhHHB",
            self.index,
            self.present_position,
            self.profile_velocity,
            self.current_limit,
            flags,
        )

    @classmethod
    def decode_payload(cls, slave: int, data: bytes) -> InitialConfig2:
        import struct

        from .errors import NeuronFrameError

        check_dlc(cls.KIND, data, (8,))
        index, position, velocity, limit, flags = struct.unpack("<BhHHB", data)
        if flags & ~0b11:
            raise NeuronFrameError(
                "reserved_bits", f"initial_config_2: flags 0x{flags:02X} has bits other than 0, 1"
            )
        return cls(slave, index, position, velocity, limit, bool(flags & 1), bool(flags & 2))


@dataclass(frozen=True)
class InitialConfig3(_Reply, StructFrame):
    """``[index, hardware_error_status, goal_current, joint_resolution, servo_resolution]``
    (last three i16), DLC 8."""

    slave: int
    index: int
    hardware_error_status: int
    goal_current: int
    joint_resolution: int
    servo_resolution: int

    KIND: ClassVar[str] = "initial_config_3"
    MESSAGE: ClassVar[int] = InitializerMessage.CONFIG_3
    CODES: ClassVar[str] = "BBhhh"
    LIMITS: ClassVar[dict[str, tuple[int, int]]] = {"index": _INDEX}


# ---------------------------------------------------------------- BOARD_CONFIG_REQUEST (S->N)


class BoardConfig(_Initializer, StructFrame):
    """Base of the board-config sub-commands; payload = ``[sub-command, ...]``."""

    DIRECTION: ClassVar[Direction] = Direction.SPINAL_TO_NEURON
    MESSAGE: ClassVar[int] = InitializerMessage.CONFIG_1
    COMMAND: ClassVar[BoardConfigCommand]


def _board(command: BoardConfigCommand, codes: str, **limits: tuple[int, int]):
    def wrap(cls):
        cls.COMMAND = command
        cls.PREFIX = bytes([command])
        cls.CODES = codes
        cls.KIND = "board_config_" + command.name.lower()
        cls.LIMITS = limits
        return dataclass(frozen=True)(cls)

    return wrap


@_board(BoardConfigCommand.SET_SLAVE_ID, "B", new_id=(1, 14))
class SetSlaveId(BoardConfig):
    slave: int
    new_id: int


@_board(BoardConfigCommand.SET_IMU_SEND_FLAG, "?")
class SetImuSendFlag(BoardConfig):
    slave: int
    flag: bool


@_board(BoardConfigCommand.SET_SERVO_HOMING_OFFSET, "Bi", index=_INDEX)
class SetServoHomingOffset(BoardConfig):
    slave: int
    index: int
    offset: int


@_board(BoardConfigCommand.SET_SERVO_PID_GAIN, "BHHH", index=_INDEX)
class SetServoPidGain(BoardConfig):
    slave: int
    index: int
    p_gain: int
    i_gain: int
    d_gain: int


@_board(BoardConfigCommand.SET_SERVO_PROFILE_VEL, "BH", index=_INDEX)
class SetServoProfileVel(BoardConfig):
    slave: int
    index: int
    profile_velocity: int


@_board(BoardConfigCommand.SET_SEND_DATA_FLAG, "B?", index=_INDEX)
class SetSendDataFlag(BoardConfig):
    slave: int
    index: int
    flag: bool


@_board(BoardConfigCommand.SET_SERVO_CURRENT_LIMIT, "BH", index=_INDEX)
class SetServoCurrentLimit(BoardConfig):
    slave: int
    index: int
    current_limit: int


@_board(BoardConfigCommand.REBOOT, "")
class Reboot(BoardConfig):
    slave: int


@_board(BoardConfigCommand.SET_DYNAMIXEL_TTL_RS485_MIXED, "?")
class SetDynamixelTtlRs485Mixed(BoardConfig):
    slave: int
    flag: bool


@_board(BoardConfigCommand.SET_EXTERNAL_ENCODER_FLAG, "B?", index=_INDEX)
class SetExternalEncoderFlag(BoardConfig):
    slave: int
    index: int
    flag: bool


@_board(BoardConfigCommand.SET_RESOLUTION_RATIO, "Bhh", index=_INDEX)
class SetResolutionRatio(BoardConfig):
    slave: int
    index: int
    joint_resolution: int
    servo_resolution: int


@_board(BoardConfigCommand.SET_SERVO_ROUND_OFFSET, "Bi", index=_INDEX)
class SetServoRoundOffset(BoardConfig):
    slave: int
    index: int
    offset: int


@_board(BoardConfigCommand.SET_SERVO_PULLEY_SKIP_THRESH, "H")
class SetServoPulleySkipThresh(BoardConfig):
    slave: int
    thresh: int


BOARD_CONFIG_CLASSES: dict[int, type[BoardConfig]] = {
    cls.COMMAND: cls
    for cls in (
        SetSlaveId,
        SetImuSendFlag,
        SetServoHomingOffset,
        SetServoPidGain,
        SetServoProfileVel,
        SetSendDataFlag,
        SetServoCurrentLimit,
        Reboot,
        SetDynamixelTtlRs485Mixed,
        SetExternalEncoderFlag,
        SetResolutionRatio,
        SetServoRoundOffset,
        SetServoPulleySkipThresh,
    )
}


def initialization_sequence(slaves: list[int]) -> list[NeuronFrame]:
    """Spinal's start-up frames: ENUM_REQUEST, then one INITIAL_CONFIG_REQUEST per Neuron in
    ascending slave-id order (200 ms apart on the real bus)."""
    for s in slaves:
        check_slave(s)
    return [EnumRequest(), *(InitialConfigRequest(s) for s in sorted(set(slaves)))]


def initial_config_reply(
    config0: InitialConfig0,
    servos: list[tuple[InitialConfig1, InitialConfig2, InitialConfig3]],
) -> list[NeuronFrame]:
    """A Neuron's answer to INITIAL_CONFIG_REQUEST (or to any board-config sub-command):
    INITIAL_CONFIG_0, then INITIAL_CONFIG_1, _2, _3 for each servo in index order.

    The per-servo order (1, 2, 3 for servo 0, then servo 1, ...) is an assumption; Spinal
    keys every frame by its servo index, so it accepts any order.
    """
    from .errors import NeuronFrameError

    if len(servos) != config0.servo_num:
        raise NeuronFrameError(
            "range", f"servo_num={config0.servo_num} but {len(servos)} servo configs given"
        )
    out: list[NeuronFrame] = [config0]
    for index, triple in enumerate(servos):
        for frame in triple:
            if frame.slave != config0.slave or frame.index != index:
                raise NeuronFrameError(
                    "range", f"{frame.KIND}: expected slave {config0.slave} index {index}"
                )
        out.extend(triple)
    return out
