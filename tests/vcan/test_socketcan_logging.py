"""Traffic logged with python-can's Logger in candump format (``candump -L``) matches what was
sent, read back with an independent parser of that format."""

from __future__ import annotations

import re
import time

import can

# "(seconds.micros) iface ID#DATA" with ID 3 (standard) or 8 (extended) hex digits, DATA hex
# pairs or "R" for a remote frame; python-can appends " R"/" T" (received/transmitted).
CANDUMP_LINE = re.compile(
    r"^\((?P<ts>\d+\.\d{6})\) (?P<iface>\S+) (?P<id>[0-9A-F]{3}|[0-9A-F]{8})"
    r"#(?P<data>(?:[0-9A-F]{2})*|R\d?)(?: (?P<dir>[RT]))?$"
)

SENT = [
    can.Message(arbitration_id=0x123, data=b"\x11\x22\x33", is_extended_id=False),
    can.Message(arbitration_id=0x00F, data=b"", is_extended_id=False),
    can.Message(arbitration_id=0x1F0E0D0C, data=bytes(range(8)), is_extended_id=True),
    can.Message(arbitration_id=0x321, is_remote_frame=True, dlc=0, is_extended_id=False),
]


def _parse(line: str) -> tuple[float, str, int, bool, bytes | None, str | None]:
    match = CANDUMP_LINE.match(line)
    assert match, f"not candump format: {line!r}"
    raw_id, data = match["id"], match["data"]
    payload = None if data.startswith("R") else bytes.fromhex(data)
    return (
        float(match["ts"]),
        match["iface"],
        int(raw_id, 16),
        len(raw_id) == 8,
        payload,
        match["dir"],
    )


def test_logger_writes_candump_lines_for_received_frames(vcan_bus, vcan_channel, tmp_path):
    path = tmp_path / "traffic.log"
    sender, receiver = vcan_bus(), vcan_bus()
    logger = can.Logger(str(path))
    assert isinstance(logger, can.CanutilsLogWriter)
    notifier = can.Notifier(receiver, [logger], timeout=0.05)
    started = time.time()
    try:
        for msg in SENT:
            sender.send(msg)
        deadline = time.monotonic() + 5.0
        while time.monotonic() < deadline:
            time.sleep(0.05)
            logger.file.flush()
            if len(path.read_text().splitlines()) >= len(SENT):
                break
    finally:
        notifier.stop()
        logger.stop()
    lines = path.read_text().splitlines()
    assert len(lines) == len(SENT)
    parsed = [_parse(line) for line in lines]
    for fields, sent in zip(parsed, SENT, strict=True):
        ts, iface, identifier, extended, payload, direction = fields
        assert iface == vcan_channel
        assert identifier == sent.arbitration_id
        assert extended == sent.is_extended_id
        assert payload == (None if sent.is_remote_frame else bytes(sent.data))
        # python-can writes T for frames sent from this host (MSG_DONTROUTE; see
        # test_locally_sent_frames_are_flagged_as_not_received): all frames on vcan.
        assert direction == "T"
        # kernel receive timestamps are wall-clock time
        assert started - 1.0 <= ts <= time.time() + 1.0
    stamps = [p[0] for p in parsed]
    assert stamps == sorted(stamps)


def test_logged_file_replays_onto_the_bus(vcan_bus, recv_all, tmp_path):
    """The candump log is also an input: python-can's LogReader replays it onto vcan0."""
    path = tmp_path / "replay.log"
    path.write_text(
        "(1700000000.000000) vcan0 0A5#0102\n"
        "(1700000000.001000) vcan0 1ABCDEF0#FFEE\n"
        "(1700000000.002000) vcan0 7FF#\n"
    )
    sender, receiver = vcan_bus(), vcan_bus()
    for msg in can.LogReader(str(path)):
        sender.send(msg)
    got = recv_all(receiver, window=5.0, limit=3)
    assert [(m.arbitration_id, m.is_extended_id, bytes(m.data)) for m in got] == [
        (0x0A5, False, b"\x01\x02"),
        (0x1ABCDEF0, True, b"\xff\xee"),
        (0x7FF, False, b""),
    ]
