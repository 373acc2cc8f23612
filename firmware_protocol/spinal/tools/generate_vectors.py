"""Regenerate ``golden_frames.json`` from the ``.msg`` tree with rosbags (not with rdm).

    python firmware_protocol/spinal/tools/generate_vectors.py          # rewrite the file
    python firmware_protocol/spinal/tools/generate_vectors.py --check  # fail if it would change

Payloads come from rosbags' ROS1 serializer, md5 sums from rosbags, frames from the separate
formula in ``rosbags_oracle.frame``; the fact sheet's example frames (sec. 1.2) are literal
strings and the script asserts that the formula reproduces them.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import rosbags_oracle as oracle

ROOT = oracle.ROOT
OUT = ROOT / "golden_frames.json"
SEED = 20261121

# jsk-wire-protocols.md sec. 1.2, copied literally
FACT_SHEET = [
    {
        "name": "server topic request",
        "hex": "FF FE 00 00 FF 00 00 FF",
        "topic_id": 0,
        "type": None,
        "fields": None,
    },
    {
        "name": "client time request",
        "hex": "FF FE 08 00 F7 0A 00 00 00 00 00 00 00 00 00 F5",
        "topic_id": 10,
        "type": "std_msgs/Time",
        "fields": {"data": {"sec": 0, "nsec": 0}},
    },
    {
        "name": "FourAxisCommand angles {0,0,0}, base_thrust {5,5,5,5} on id 108",
        "hex": "FF FE 20 00 DF 6C 00" + " 00" * 12 + " 04 00 00 00" + " 00 00 A0 40" * 4 + " 0F",
        "topic_id": 108,
        "type": "spinal/FourAxisCommand",
        "fields": {"angles": [0.0, 0.0, 0.0], "base_thrust": [5.0, 5.0, 5.0, 5.0]},
    },
]


def entry(ts, name: str, topic_id: int, type_: str | None, fields: dict | None, **extra) -> dict:
    payload = b"" if type_ is None else oracle.serialize(ts, oracle.rosbags_name(type_), fields)
    return {
        "name": name,
        "topic_id": topic_id,
        "type": type_,
        "fields": fields,
        "hex": oracle.frame(topic_id, payload).hex(),
        **extra,
    }


def build() -> dict:
    ts = oracle.make_typestore()
    rng = np.random.default_rng(SEED)
    layout = json.loads((ROOT / "layout_stm32H7_v2.json").read_text())
    for ex in FACT_SHEET:
        payload = (
            b""
            if ex["type"] is None
            else oracle.serialize(ts, oracle.rosbags_name(ex["type"]), ex["fields"])
        )
        computed = oracle.frame(ex["topic_id"], payload)
        assert computed == bytes.fromhex(ex["hex"]), (ex["name"], computed.hex())

    def md5_of(row: dict, half: str) -> str:
        if row["kind"] == "topic":
            return oracle.md5(ts, oracle.rosbags_name(row["type"]))
        return oracle.md5(ts, oracle.rosbags_name(row["type"]) + half)

    info = "rosserial_msgs/TopicInfo"
    reply = [entry(ts, "time request", 10, "std_msgs/Time", {"data": {"sec": 0, "nsec": 0}})]
    for row in layout["publishers"]:
        service = row["kind"] == "service_response"
        fields = {
            "topic_id": row["id"],
            "topic_name": row["name"],
            "message_type": row["type"],
            "md5sum": md5_of(row, "Response"),
            "buffer_size": layout["output_size"],
        }
        reply.append(
            entry(ts, f"TopicInfo publisher {row['name']}", 2 if service else 0, info, fields)
        )
    for row in layout["subscribers"]:
        service = row["kind"] == "service_request"
        fields = {
            "topic_id": row["id"],
            "topic_name": row["name"],
            "message_type": row["type"],
            "md5sum": md5_of(row, "Request"),
            "buffer_size": layout["input_size"],
        }
        reply.append(
            entry(ts, f"TopicInfo subscriber {row['name']}", 3 if service else 1, info, fields)
        )

    time_answer = {"data": {"sec": 1767225600, "nsec": 250000000}}
    reserved = [
        entry(ts, "time answer", 10, "std_msgs/Time", time_answer),
        entry(
            ts,
            "log error (frame too large)",
            7,
            "rosserial_msgs/Log",
            {"level": 3, "msg": "Message from device dropped: message larger than buffer."},
        ),
        entry(ts, "log info", 7, "rosserial_msgs/Log", {"level": 1, "msg": "imu calibrated"}),
        entry(ts, "TX_STOP", 11, None, None),
    ]

    topics = []
    for direction, rows, half in (
        ("pc_to_spinal", layout["subscribers"], "Request"),
        ("spinal_to_pc", layout["publishers"], "Response"),
    ):
        for row in rows:
            type_ = row["type"] if row["kind"] == "topic" else row["type"] + half
            for k in range(2):
                fields = oracle.random_fields(ts, oracle.rosbags_name(type_), rng)
                topics.append(
                    entry(
                        ts,
                        f"{row['name']} #{k}",
                        row["id"],
                        type_,
                        fields,
                        topic=row["name"],
                        direction=direction,
                    )
                )

    good = bytes.fromhex(topics[0]["hex"])
    oversize = bytes([0xFF, 0xFE, 0x58, 0x02, (255 - (0x58 + 0x02) % 256), 0x6C, 0x00]) + bytes(601)
    bad = [
        {
            "name": "length checksum off by one",
            "reason": "length_checksum",
            "hex": (good[:4] + bytes([(good[4] + 1) % 256]) + good[5:]).hex(),
        },
        {
            "name": "message checksum off by one",
            "reason": "message_checksum",
            "hex": (good[:-1] + bytes([(good[-1] + 1) % 256])).hex(),
        },
        {
            "name": "payload byte flipped",
            "reason": "message_checksum",
            "hex": (good[:8] + bytes([good[8] ^ 0x10]) + good[9:]).hex(),
        },
        {
            "name": "protocol version 0xFF (v1)",
            "reason": "version",
            "hex": (good[:1] + b"\xff" + good[2:]).hex(),
        },
        {
            "name": "600-byte payload: above Spinal's 512-byte input buffer",
            "reason": "oversize",
            "receiver": "client",
            "hex": oversize.hex(),
        },
    ]
    return {
        "_about": "rosserial v2 frames of the Spinal link (tools/generate_vectors.py)",
        "fact_sheet_examples": FACT_SHEET,
        "handshake": {
            "layout": "layout_stm32H7_v2.json",
            "server_request": oracle.frame(0, b"").hex(),
            "client_reply": reply,
        },
        "reserved": reserved,
        "topics": topics,
        "bad_frames": bad,
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="compare instead of writing")
    args = parser.parse_args()
    text = json.dumps(build(), indent=1) + "\n"
    if args.check:
        same = OUT.exists() and OUT.read_text() == text
        print("golden_frames.json is up to date" if same else "golden_frames.json is STALE")
        return 0 if same else 1
    OUT.write_text(text)
    print(f"wrote {OUT}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
