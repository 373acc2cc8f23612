#!/usr/bin/env python3
"""Write ``vectors.json``: golden Leptrino frames built byte by byte the way the sensor/host
C code frames them (jsk-wire-protocols.md sec. 5). Stand-alone (no import of rdm)."""

from __future__ import annotations

import json
import struct
from pathlib import Path

HERE = Path(__file__).resolve().parent
DLE, STX, ETX = 0x10, 0x02, 0x03


def send_data(payload: bytes) -> bytes:
    """Leptrino SendData: DLE STX, each byte (0x10 doubled), DLE ETX, BCC (XOR incl. ETX)."""
    out = [DLE, STX]
    check = 0
    for b in payload:
        if b == DLE:
            out.append(DLE)  # stuffing byte is not part of the BCC
        out.append(b)
        check ^= b
    check ^= ETX
    out += [DLE, ETX, check]
    return bytes(out)


def cmd(code: int, extra: bytes = b"") -> bytes:
    body = bytes([0]) + extra
    return bytes([3 + len(body), 0xFF, code]) + body


def vec(name, role, payload, kind, **fields):
    return {
        "name": name,
        "role": role,
        "payload": payload.hex(),
        "frame": send_data(payload).hex(),
        "kind": kind,
        "fields": fields,
    }


def vectors():
    v = [
        vec(
            "get_product_info",
            "host",
            cmd(0x2A),
            "command",
            command="GET_INF",
            sensor_no=255,
            digital_filter=None,
        ),
        vec(
            "get_rated_values",
            "host",
            cmd(0x2B),
            "command",
            command="GET_LIMIT",
            sensor_no=255,
            digital_filter=None,
        ),
        vec(
            "start_continuous",
            "host",
            cmd(0x32),
            "command",
            command="DATA_START",
            sensor_no=255,
            digital_filter=None,
        ),
        vec(
            "stop_continuous",
            "host",
            cmd(0x33),
            "command",
            command="DATA_STOP",
            sensor_no=255,
            digital_filter=None,
        ),
        vec(
            "get_digital_filter",
            "host",
            cmd(0xB6),
            "command",
            command="GET_DF",
            sensor_no=255,
            digital_filter=None,
        ),
        vec(
            "set_digital_filter",
            "host",
            cmd(0xA6, bytes([0x10, 0, 0, 0])),
            "command",
            command="SET_DF",
            sensor_no=255,
            digital_filter=16,
        ),
    ]
    # Data: raw values containing 0x10 bytes (stuffing) and full scale.
    raw = [10000, -10000, 0x1010, -16, 4112, 0]
    data = struct.pack("<4B6hhBB", 20, 0, 0x32, 0, *raw, 2500, 0x10, 0)
    v.append(
        vec(
            "force_data_stuffed",
            "sensor",
            data,
            "force_data",
            raw=raw,
            temperature=2500,
            status=16,
            result=0,
            term_no=0,
        )
    )
    # A sample whose BCC is itself 0x10: the BCC goes out raw (not doubled).
    for temp in range(0, 512):
        d = struct.pack("<4B6hhBB", 20, 0, 0x32, 0, 1, 2, 3, 4, 5, 6, temp, 0, 0)
        check = ETX
        for b in d:
            check ^= b
        if check == DLE:
            v.append(
                vec(
                    "force_data_bcc_is_dle",
                    "sensor",
                    d,
                    "force_data",
                    raw=[1, 2, 3, 4, 5, 6],
                    temperature=temp,
                    status=0,
                    result=0,
                    term_no=0,
                )
            )
            break
    info = struct.pack(
        "<4B16s8s4s6s", 38, 0, 0x2A, 0, b"CFS034CA301U", b"A1234567", b"1.02", b"1200Hz"
    )
    v.append(
        vec(
            "product_info",
            "sensor",
            info,
            "product_info",
            product_name="CFS034CA301U",
            serial="A1234567",
            firmware_version="1.02",
            output_rate="1200Hz",
            result=0,
            term_no=0,
        )
    )
    lim = struct.pack("<4B6f", 28, 0, 0x2B, 0, 100.0, 100.0, 200.0, 1.0, 1.0, 1.0)
    v.append(
        vec(
            "rated_values_cfs018",
            "sensor",
            lim,
            "rated_values",
            limits=[100.0, 100.0, 200.0, 1.0, 1.0, 1.0],
            result=0,
            term_no=0,
        )
    )
    v.append(
        vec("stop_ack", "sensor", bytes([4, 0, 0x33, 0]), "ack", command=0x33, result=0, term_no=0)
    )
    v.append(
        vec(
            "undefined_command_error",
            "sensor",
            bytes([4, 0, 0x2B, 2]),
            "ack",
            command=0x2B,
            result=2,
            term_no=0,
        )
    )
    v.append(
        vec(
            "digital_filter",
            "sensor",
            bytes([8, 0, 0xB6, 0, 3, 0, 0, 0]),
            "digital_filter",
            digital_filter=3,
            result=0,
            term_no=0,
        )
    )
    return v


def main() -> None:
    doc = {
        "description": "Golden Leptrino F/T sensor frames: 'payload' unstuffed, 'frame' as on "
        "the wire (DLE STX ... DLE ETX BCC). role=host: host command; role=sensor: response.",
        "vectors": vectors(),
    }
    (HERE / "vectors.json").write_text(json.dumps(doc, indent=1) + "\n")


if __name__ == "__main__":
    main()
