#!/usr/bin/env python3
"""Write the Neuron CAN DBC files from the fact-sheet tables (jsk-wire-protocols.md sec. 2).

Stand-alone on purpose (no import of rdm): the DBCs are an independent description that the
tests hold the Python codec against. Run ``python generate_dbc.py`` in this folder.

Three files, because request and response frames share CAN ids and a DBC maps one id to one
message:
* ``neuron_spinal_to_neuron.dbc``: every frame Spinal transmits;
* ``neuron_neuron_to_spinal.dbc``: every frame a Neuron transmits;
* ``neuron.dbc``: the bus view for sniffing (``cantools decode``): all Neuron->Spinal frames
  plus the Spinal frames whose ids are not shared (PWM, ENUM_REQUEST). INITIAL_CONFIG_REQUEST
  is the DLC-0 form of ``InitialConfig0``; the servo target and board-config frames are only
  in ``neuron_spinal_to_neuron.dbc``.
"""

from __future__ import annotations

import math
from pathlib import Path

HERE = Path(__file__).resolve().parent
SLAVES = range(1, 15)
BROADCAST = 15

GYRO = (2000.0 / 32767.0) * math.pi / 180.0
ACC = 9.80665 / 4096.0
MAG = 4912.0 / 32760.0


def cid(device: int, message: int, slave: int) -> int:
    return (device << 8) | (message << 4) | slave


def sig(name, start, length, signed=False, scale=1, offset=0, lo=None, hi=None, unit="", mux=""):
    if lo is None:
        lo = -(1 << (length - 1)) if signed else 0
    if hi is None:
        hi = (1 << (length - 1)) - 1 if signed else (1 << length) - 1
        lo, hi = lo * scale + offset, hi * scale + offset
    mux = f" {mux}" if mux else ""
    sign = "-" if signed else "+"
    return (
        f' SG_ {name}{mux} : {start}|{length}@1{sign} ({scale!r},{offset}) [{lo!r}|{hi!r}] "{unit}"'
    )


class Msg:
    def __init__(
        self,
        name,
        frame_id,
        dlc,
        sender,
        signals,
        comment,
        dev,
        msg,
        slave,
        direction,
        choices=None,
    ):
        self.name, self.frame_id, self.dlc, self.sender = name, frame_id, dlc, sender
        self.signals, self.comment, self.choices = signals, comment, choices or {}
        self.dev, self.msg, self.slave, self.direction = dev, msg, slave, direction

    def text(self) -> str:
        receiver = "NEURON" if self.sender == "SPINAL" else "SPINAL"
        lines = [f"BO_ {self.frame_id} {self.name}: {self.dlc} {self.sender}"]
        lines += [s + f" {receiver}" for s in self.signals]
        return "\n".join(lines)


def pwm_messages():
    out = []
    for m, first in ((0, 1), (1, 7)):
        signals = [
            sig(f"Pwm{first + k}", 10 * (k % 3) + 32 * (k // 3), 10, lo=0, hi=1000, unit="us")
            for k in range(6)
        ]
        out.append(
            Msg(
                f"MotorPwmSlaves{first}To{first + 5}",
                cid(0, m, BROADCAST),
                8,
                "SPINAL",
                signals,
                f"PWM value = pulse_us - 1000 (0..1000) for Neuron slaves "
                f"{first}..{first + 5}, six 10-bit values LSB-first.",
                0,
                m,
                BROADCAST,
                "spinal_to_neuron",
            )
        )
    return out


def spinal_tx():
    out = pwm_messages()
    out.append(
        Msg(
            "EnumRequest",
            cid(7, 0, BROADCAST),
            0,
            "SPINAL",
            [],
            "ENUM_REQUEST broadcast; every Neuron answers with EnumResponse.",
            7,
            0,
            BROADCAST,
            "spinal_to_neuron",
        )
    )
    sub = {
        0: "SET_SLAVE_ID",
        1: "SET_IMU_SEND_FLAG",
        2: "SET_SERVO_HOMING_OFFSET",
        3: "SET_SERVO_PID_GAIN",
        4: "SET_SERVO_PROFILE_VEL",
        5: "SET_SEND_DATA_FLAG",
        6: "SET_SERVO_CURRENT_LIMIT",
        7: "REBOOT",
        8: "SET_DYNAMIXEL_TTL_RS485_MIXED",
        9: "SET_EXTERNAL_ENCODER_FLAG",
        10: "SET_RESOLUTION_RATIO",
        11: "SET_SERVO_ROUND_OFFSET",
        12: "SET_SERVO_PULLEY_SKIP_THRESH",
    }
    for s in SLAVES:
        for m, name, value, flag in (
            (0, "ServoTargetAngle", "GoalPosition", "GoalAck"),
            (1, "ServoTargetCurrent", "GoalCurrent", "TorqueEnable"),
        ):
            signals = []
            for i in range(4):
                signals.append(sig(f"Servo{i}{value}", 16 * i, 15, signed=True))
                signals.append(sig(f"Servo{i}{flag}", 16 * i + 15, 1))
            out.append(
                Msg(
                    f"{name}_S{s:02d}",
                    cid(2, m, s),
                    8,
                    "SPINAL",
                    signals,
                    f"One uint16 per servo (DLC = 2 x servo_num): bits 14..0 15-bit "
                    f"signed {value}, bit 15 {flag}.",
                    2,
                    m,
                    s,
                    "spinal_to_neuron",
                )
            )
        out.append(
            Msg(
                f"InitialConfigRequest_S{s:02d}",
                cid(7, 1, s),
                0,
                "SPINAL",
                [],
                "INITIAL_CONFIG_REQUEST (DLC 0).",
                7,
                1,
                s,
                "spinal_to_neuron",
            )
        )
        idx = lambda name, m: sig(name, 8, 8, lo=0, hi=3, mux=f"m{m}")  # noqa: E731
        board = [
            sig("SubCommand", 0, 8, lo=0, hi=12, mux="M"),
            sig("NewSlaveId", 8, 8, lo=1, hi=14, mux="m0"),
            sig("ImuSendFlag", 8, 8, lo=0, hi=1, mux="m1"),
            idx("HomingOffsetIndex", 2),
            sig("HomingOffset", 16, 32, signed=True, mux="m2"),
            idx("PidGainIndex", 3),
            sig("PGain", 16, 16, mux="m3"),
            sig("IGain", 32, 16, mux="m3"),
            sig("DGain", 48, 16, mux="m3"),
            idx("ProfileVelIndex", 4),
            sig("ProfileVelocity", 16, 16, mux="m4"),
            idx("SendDataFlagIndex", 5),
            sig("SendDataFlag", 16, 8, lo=0, hi=1, mux="m5"),
            idx("CurrentLimitIndex", 6),
            sig("CurrentLimit", 16, 16, mux="m6"),
            sig("TtlRs485Mixed", 8, 8, lo=0, hi=1, mux="m8"),
            idx("ExternalEncoderIndex", 9),
            sig("ExternalEncoderFlag", 16, 8, lo=0, hi=1, mux="m9"),
            idx("ResolutionIndex", 10),
            sig("JointResolution", 16, 16, signed=True, mux="m10"),
            sig("ServoResolution", 32, 16, signed=True, mux="m10"),
            idx("RoundOffsetIndex", 11),
            sig("RoundOffset", 16, 32, signed=True, mux="m11"),
            sig("PulleySkipThresh", 8, 16, mux="m12"),
        ]
        out.append(
            Msg(
                f"BoardConfigRequest_S{s:02d}",
                cid(7, 2, s),
                8,
                "SPINAL",
                board,
                "BOARD_CONFIG_REQUEST; real DLC = 1 + sub-command payload "
                "(2,2,6,8,4,3,4,1,2,3,6,6,3 for sub-commands 0..12).",
                7,
                2,
                s,
                "spinal_to_neuron",
                choices={"SubCommand": sub},
            )
        )
    return out


def neuron_tx(merge_config_request: bool = False):
    out = []
    for s in SLAVES:
        for m, kind, scale, unit in (
            (0, "Gyro", GYRO, "rad/s"),
            (1, "Acc", ACC, "m/s^2"),
            (2, "Mag", MAG, "uT"),
        ):
            signals = [
                sig(f"{kind}{a}", 16 * k, 16, signed=True, scale=scale, unit=unit)
                for k, a in enumerate("XYZ")
            ]
            out.append(
                Msg(
                    f"Imu{kind}_S{s:02d}",
                    cid(1, m, s),
                    6,
                    "NEURON",
                    signals,
                    f"MPU9250 {kind} in the sensor frame (Spinal remaps axes after scaling).",
                    1,
                    m,
                    s,
                    "neuron_to_spinal",
                )
            )
        for i in range(4):
            signals = [
                sig("Angle", 0, 16, signed=True),
                sig("Temperature", 16, 8),
                sig("ForceServoOff", 24, 1),
                sig("Moving", 25, 1),
                sig("GoalReported", 26, 1),
                sig("Current", 32, 16, signed=True),
                sig("ServoError", 48, 8),
            ]
            out.append(
                Msg(
                    f"ServoState{i}_S{s:02d}",
                    cid(2, i, s),
                    8,
                    "NEURON",
                    signals,
                    f"State of servo index {i}; byte 7 is padding.",
                    2,
                    i,
                    s,
                    "neuron_to_spinal",
                )
            )
        out.append(
            Msg(
                f"EnumResponse_S{s:02d}",
                cid(7, 0, s),
                0,
                "NEURON",
                [],
                "ENUM_RESPONSE (DLC 0).",
                7,
                0,
                s,
                "neuron_to_spinal",
            )
        )
        note = (
            " DLC 0 on this id is Spinal's INITIAL_CONFIG_REQUEST." if merge_config_request else ""
        )
        out.append(
            Msg(
                f"InitialConfig0_S{s:02d}",
                cid(7, 1, s),
                5,
                "NEURON",
                [
                    sig("ServoNum", 0, 8, lo=0, hi=4),
                    sig("ImuSendFlag", 8, 8, lo=0, hi=1),
                    sig("TtlRs485Mixed", 16, 8, lo=0, hi=1),
                    sig("PulleySkipThresh", 24, 16),
                ],
                "INITIAL_CONFIG_0." + note,
                7,
                1,
                s,
                "neuron_to_spinal",
            )
        )
        out.append(
            Msg(
                f"InitialConfig1_S{s:02d}",
                cid(7, 2, s),
                8,
                "NEURON",
                [
                    sig("Index", 0, 8, lo=0, hi=3),
                    sig("DynamixelId", 8, 8),
                    sig("PGain", 16, 16),
                    sig("IGain", 32, 16),
                    sig("DGain", 48, 16),
                ],
                "INITIAL_CONFIG_1, one per servo.",
                7,
                2,
                s,
                "neuron_to_spinal",
            )
        )
        out.append(
            Msg(
                f"InitialConfig2_S{s:02d}",
                cid(7, 3, s),
                8,
                "NEURON",
                [
                    sig("Index", 0, 8, lo=0, hi=3),
                    sig("PresentPosition", 8, 16, signed=True),
                    sig("ProfileVelocity", 24, 16),
                    sig("CurrentLimit", 40, 16),
                    sig("SendDataFlag", 56, 1),
                    sig("ExternalEncoderFlag", 57, 1),
                ],
                "INITIAL_CONFIG_2, one per servo.",
                7,
                3,
                s,
                "neuron_to_spinal",
            )
        )
        out.append(
            Msg(
                f"InitialConfig3_S{s:02d}",
                cid(7, 4, s),
                8,
                "NEURON",
                [
                    sig("Index", 0, 8, lo=0, hi=3),
                    sig("HardwareErrorStatus", 8, 8),
                    sig("GoalCurrent", 16, 16, signed=True),
                    sig("JointResolution", 32, 16, signed=True),
                    sig("ServoResolution", 48, 16, signed=True),
                ],
                "INITIAL_CONFIG_3, one per servo.",
                7,
                4,
                s,
                "neuron_to_spinal",
            )
        )
    return out


def render(messages, title: str) -> str:
    ids = [m.frame_id for m in messages]
    assert len(ids) == len(set(ids)), "duplicate CAN id in one DBC"
    parts = [
        'VERSION ""',
        "",
        "NS_ :",
        "\tCM_",
        "\tBA_DEF_",
        "\tBA_",
        "\tVAL_",
        "\tBA_DEF_DEF_",
        "",
        "BS_:",
        "",
        "BU_: SPINAL NEURON",
        "",
        "",
    ]
    parts += [m.text() + "\n" for m in sorted(messages, key=lambda m: m.frame_id)]
    parts.append("")
    parts.append(
        f'CM_ "{title} Generated by generate_dbc.py from jsk-wire-protocols.md sec. 2. '
        'Id = device<<8 | message<<4 | slave; 1 Mbit/s classic CAN, little-endian.";'
    )
    for m in messages:
        parts.append(f'CM_ BO_ {m.frame_id} "{m.comment}";')
    parts += [
        'BA_DEF_ BO_ "NeuronDevice" INT 0 7;',
        'BA_DEF_ BO_ "NeuronMessage" INT 0 15;',
        'BA_DEF_ BO_ "NeuronSlave" INT 0 15;',
        'BA_DEF_ BO_ "NeuronDirection" STRING ;',
        'BA_DEF_DEF_ "NeuronDevice" 0;',
        'BA_DEF_DEF_ "NeuronMessage" 0;',
        'BA_DEF_DEF_ "NeuronSlave" 0;',
        'BA_DEF_DEF_ "NeuronDirection" "";',
    ]
    for m in messages:
        parts.append(f'BA_ "NeuronDevice" BO_ {m.frame_id} {m.dev};')
        parts.append(f'BA_ "NeuronMessage" BO_ {m.frame_id} {m.msg};')
        parts.append(f'BA_ "NeuronSlave" BO_ {m.frame_id} {m.slave};')
        parts.append(f'BA_ "NeuronDirection" BO_ {m.frame_id} "{m.direction}";')
    for m in messages:
        for signal, table in m.choices.items():
            entries = " ".join(f'{k} "{v}"' for k, v in sorted(table.items(), reverse=True))
            parts.append(f"VAL_ {m.frame_id} {signal} {entries} ;")
    return "\n".join(parts) + "\n"


def main() -> None:
    s2n = spinal_tx()
    n2s = neuron_tx()
    bus = neuron_tx(merge_config_request=True) + [
        m for m in s2n if m.name.startswith(("MotorPwm", "EnumRequest"))
    ]
    (HERE / "neuron_spinal_to_neuron.dbc").write_text(
        render(s2n, "Neuron CAN link: frames sent by Spinal.")
    )
    (HERE / "neuron_neuron_to_spinal.dbc").write_text(
        render(n2s, "Neuron CAN link: frames sent by Neurons.")
    )
    (HERE / "neuron.dbc").write_text(render(bus, "Neuron CAN link: bus view for sniffing."))


if __name__ == "__main__":
    main()
