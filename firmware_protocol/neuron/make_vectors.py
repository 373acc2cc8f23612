#!/usr/bin/env python3
"""Write ``vectors.json``: golden Neuron CAN frames built straight from the fact-sheet byte
tables (jsk-wire-protocols.md sec. 2.4) with ``struct`` and explicit bit formulas.

Stand-alone on purpose (no import of rdm) so the vectors are independent of the codec.
"""

from __future__ import annotations

import json
import math
import struct
from pathlib import Path

HERE = Path(__file__).resolve().parent


def cid(device: int, message: int, slave: int) -> int:
    return (device << 8) | (message << 4) | slave


def pwm_bytes(v: list[int]) -> bytes:
    # d0 = v0[7:0]; d1 = v1[5:0]<<2 | v0[9:8]; d2 = v2[3:0]<<4 | v1[9:6]; d3 = v2[9:4]
    out = []
    for a, b, c in (v[0:3], v[3:6]):
        out += [a & 0xFF, ((b & 0x3F) << 2) | (a >> 8), ((c & 0x0F) << 4) | (b >> 6), c >> 4]
    return bytes(out)


def word(value: int, flag: int) -> int:
    return (flag << 15) | (value & 0x7FFF)


def vec(name, direction, can_id, data, kind, **fields):
    return {
        "name": name,
        "direction": direction,
        "id": f"0x{can_id:03X}",
        "data": data.hex(),
        "kind": kind,
        "fields": fields,
    }


S2N, N2S = "spinal_to_neuron", "neuron_to_spinal"


def vectors() -> list[dict]:
    v = []
    # Motor PWM: 8 motors -> frame 0 full, frame 1 with two values and zeros.
    p0 = [0, 180, 1000, 512, 1023 - 23, 333]
    v.append(
        vec("pwm_slaves_1_6", S2N, cid(0, 0, 15), pwm_bytes(p0), "pwm", frame_index=0, values=p0)
    )
    p1 = [700, 650, 0, 0, 0, 0]
    v.append(
        vec("pwm_slaves_7_12", S2N, cid(0, 1, 15), pwm_bytes(p1), "pwm", frame_index=1, values=p1)
    )
    # IMU raw + Spinal-frame expectation (scale then remap).
    g = (2000 / 32767) * math.pi / 180
    a = 9.80665 / 4096
    m = 4912 / 32760
    for msg, sensor, raw, scale, remap in (
        (0, "gyro", (100, -200, 32767), g, lambda x, y, z: (-y, x, z)),
        (1, "acc", (-4096, 0, 4096), a, lambda x, y, z: (-y, x, z)),
        (2, "mag", (-32768, 1234, -77), m, lambda x, y, z: (-x, y, -z)),
    ):
        d = vec(
            f"imu_{sensor}",
            N2S,
            cid(1, msg, 5),
            struct.pack("<hhh", *raw),
            "imu",
            slave=5,
            sensor=sensor,
            x=raw[0],
            y=raw[1],
            z=raw[2],
        )
        d["spinal_frame"] = [c * scale for c in remap(*raw)]
        v.append(d)
    # Servo target angle: 2 servos, servo 0 ack with negative goal, servo 1 no ack.
    v.append(
        vec(
            "servo_target_angle_2",
            S2N,
            cid(2, 0, 3),
            struct.pack("<2H", word(-1234, 1), word(2048, 0)),
            "servo_target_angle",
            slave=3,
            values=[-1234, 2048],
            flags=[True, False],
        )
    )
    v.append(
        vec(
            "servo_target_current_4",
            S2N,
            cid(2, 1, 3),
            struct.pack("<4H", word(100, 1), word(-16384, 1), word(16383, 0), word(0, 0)),
            "servo_target_current",
            slave=3,
            values=[100, -16384, 16383, 0],
            flags=[True, True, False, False],
        )
    )
    # Servo state index 2, goal reported + moving, error: pulley skip.
    v.append(
        vec(
            "servo_state_2",
            N2S,
            cid(2, 2, 3),
            struct.pack("<hBBhBB", -2000, 45, 0b110, -300, 0b10, 0),
            "servo_state",
            slave=3,
            index=2,
            angle=-2000,
            temperature=45,
            force_servo_off=False,
            moving=True,
            goal_reported=True,
            current=-300,
            servo_error=2,
        )
    )
    v.append(
        vec(
            "servo_state_0_off",
            N2S,
            cid(2, 0, 14),
            struct.pack("<hBBhBB", 4095, 30, 0b001, 0, 0, 0),
            "servo_state",
            slave=14,
            index=0,
            angle=4095,
            temperature=30,
            force_servo_off=True,
            moving=False,
            goal_reported=False,
            current=0,
            servo_error=0,
        )
    )
    # Initializer.
    v.append(vec("enum_request", S2N, cid(7, 0, 15), b"", "enum_request"))
    v.append(vec("enum_response", N2S, cid(7, 0, 4), b"", "enum_response", slave=4))
    v.append(
        vec("initial_config_request", S2N, cid(7, 1, 4), b"", "initial_config_request", slave=4)
    )
    v.append(
        vec(
            "initial_config_0",
            N2S,
            cid(7, 1, 4),
            bytes([2, 1, 0, 0x34, 0x12]),
            "initial_config_0",
            slave=4,
            servo_num=2,
            imu_send_flag=True,
            ttl_rs485_mixed=False,
            pulley_skip_thresh=0x1234,
        )
    )
    v.append(
        vec(
            "initial_config_1",
            N2S,
            cid(7, 2, 4),
            struct.pack("<BBHHH", 1, 7, 800, 0, 9000),
            "initial_config_1",
            slave=4,
            index=1,
            dynamixel_id=7,
            p_gain=800,
            i_gain=0,
            d_gain=9000,
        )
    )
    v.append(
        vec(
            "initial_config_2",
            N2S,
            cid(7, 3, 4),
            struct.pack("<BhHHB", 1, -1500, 60, 1200, 0b11),
            "initial_config_2",
            slave=4,
            index=1,
            present_position=-1500,
            profile_velocity=60,
            current_limit=1200,
            send_data_flag=True,
            external_encoder_flag=True,
        )
    )
    v.append(
        vec(
            "initial_config_3",
            N2S,
            cid(7, 4, 4),
            struct.pack("<BBhhh", 1, 0x80, -50, 4096, -2048),
            "initial_config_3",
            slave=4,
            index=1,
            hardware_error_status=0x80,
            goal_current=-50,
            joint_resolution=4096,
            servo_resolution=-2048,
        )
    )
    board = [
        ("set_slave_id", 0, "<B", dict(new_id=9)),
        ("set_imu_send_flag", 1, "<B", dict(flag=True)),
        ("set_servo_homing_offset", 2, "<Bi", dict(index=3, offset=-100000)),
        ("set_servo_pid_gain", 3, "<BHHH", dict(index=0, p_gain=640, i_gain=10, d_gain=4000)),
        ("set_servo_profile_vel", 4, "<BH", dict(index=1, profile_velocity=300)),
        ("set_send_data_flag", 5, "<BB", dict(index=2, flag=False)),
        ("set_servo_current_limit", 6, "<BH", dict(index=3, current_limit=1193)),
        ("reboot", 7, "<", {}),
        ("set_dynamixel_ttl_rs485_mixed", 8, "<B", dict(flag=True)),
        ("set_external_encoder_flag", 9, "<BB", dict(index=0, flag=True)),
        (
            "set_resolution_ratio",
            10,
            "<Bhh",
            dict(index=1, joint_resolution=4096, servo_resolution=-4096),
        ),
        ("set_servo_round_offset", 11, "<Bi", dict(index=2, offset=2**31 - 1)),
        ("set_servo_pulley_skip_thresh", 12, "<H", dict(thresh=65535)),
    ]
    for name, sub, fmt, fields in board:
        data = bytes([sub]) + struct.pack(fmt, *[int(x) for x in fields.values()])
        v.append(
            vec(
                f"board_config_{name}",
                S2N,
                cid(7, 2, 6),
                data,
                f"board_config_{name}",
                slave=6,
                **fields,
            )
        )
    return v


def main() -> None:
    doc = {
        "description": "Golden Neuron CAN frames (classic CAN, 11-bit ids). Built by "
        "make_vectors.py from jsk-wire-protocols.md sec. 2.4 with struct/bit formulas. "
        "'fields' use the names of rdm.protocol.neuron dataclasses; 'spinal_frame' on IMU "
        "vectors is the scaled, axis-remapped reading Spinal computes.",
        "vectors": vectors(),
    }
    (HERE / "vectors.json").write_text(json.dumps(doc, indent=1) + "\n")


if __name__ == "__main__":
    main()
