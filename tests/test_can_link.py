"""CAN link: spec strings, virtual buses, SocketCAN error path, candump log round trip."""

from __future__ import annotations

import socket
import time

import can
import pytest

from rdm.link.can import (
    CanSpecError,
    CanUnavailableError,
    candump_logger,
    neuron_message,
    open_can,
    parse_can_spec,
    socketcan_available,
)
from rdm.protocol import neuron as nr


def test_two_virtual_buses_on_one_channel_exchange_frames():
    frames = [
        *nr.pack_pwm([100, 200, 300, 400, 500, 600, 700]),
        nr.ServoTargetAngles(2, (10, -10), (False, True)),
        nr.ImuFrame(2, nr.ImuMessage.ACC, 1, 2, 4096),
    ]
    with open_can("virtual:rdm_test_exchange") as tx, open_can("virtual:rdm_test_exchange") as rx:
        for f in frames:
            tx.send(neuron_message(f.can_id, f.encode()))
        got = [rx.recv(timeout=1.0) for _ in frames]
        assert rx.recv(timeout=0.05) is None  # nothing else, and tx does not hear itself
        assert tx.recv(timeout=0.05) is None
    decoded = [
        nr.decode_frame(m.arbitration_id, bytes(m.data), f.DIRECTION)
        for m, f in zip(got, frames, strict=True)
    ]
    assert decoded == frames
    assert all(not m.is_extended_id for m in got)


def test_virtual_buses_on_other_channels_are_isolated():
    with open_can("virtual:rdm_iso_a,bitrate=1000000") as a, open_can("virtual:rdm_iso_b") as b:
        a.send(neuron_message(0x70F, b""))
        assert b.recv(timeout=0.05) is None


@pytest.mark.parametrize(
    ("spec", "match"),
    [
        ("vcan0", "expected '<interface>:<channel>"),
        ("pcan:PCAN_USBBUS1", "unknown interface 'pcan'"),
        ("socketcan:", "channel ''"),
        ("socketcan:can 0", "channel"),
        ("socketcan:averyveryverylongname", "channel"),
        ("virtual:bus,bitrate=fast", "bitrate 'fast'"),
        ("virtual:bus,bitrate=1", "bitrate '1'"),
        ("virtual:bus,speed=1", "unknown option 'speed'"),
        ("virtual:bus,bitrate", "not key=value"),
        ("socketcan:can0,bitrate=1000000", "ip link set can0 type can bitrate 1000000"),
        ("virtual:bus,receive_own_messages=yes", "0 or 1"),
    ],
)
def test_malformed_specs_raise_clear_errors(spec, match):
    with pytest.raises(CanSpecError, match=match):
        parse_can_spec(spec)
    with pytest.raises(CanSpecError):
        open_can(spec)


def test_spec_parsing():
    s = parse_can_spec("Virtual:hil,bitrate=500000,receive_own_messages=1")
    assert (s.interface, s.channel, s.bitrate, s.receive_own_messages) == (
        "virtual",
        "hil",
        500000,
        True,
    )
    assert parse_can_spec("socketcan:vcan0").bus_kwargs() == {
        "interface": "socketcan",
        "channel": "vcan0",
        "receive_own_messages": False,
    }


def _has_vcan0() -> bool:
    try:
        socket.if_nametoindex("vcan0")
    except OSError:
        return False
    return True


def test_socketcan_unavailable_gives_clear_error():
    if _has_vcan0() and socketcan_available("vcan0"):
        pytest.skip("vcan0 exists on this kernel: SocketCAN works here (covered by vcan tests)")
    with pytest.raises(CanUnavailableError, match=r"virtual:.*vcan VM harness") as info:
        open_can("socketcan:vcan0")
    assert isinstance(info.value, OSError)
    assert not socketcan_available("vcan0")


def test_socketcan_missing_interface_gives_clear_error():
    with pytest.raises(CanUnavailableError, match="rdmnosuch0"):
        open_can("socketcan:rdmnosuch0")


@pytest.mark.vcan
@pytest.mark.skipif(not _has_vcan0(), reason="needs kernel vcan0 (vcan VM harness)")
def test_socketcan_vcan_exchange():
    with open_can("socketcan:vcan0") as tx, open_can("socketcan:vcan0") as rx:
        tx.send(neuron_message(0x70F, b""))
        msg = rx.recv(timeout=1.0)
    assert msg is not None and msg.arbitration_id == 0x70F and msg.dlc == 0


def test_candump_log_written_by_python_can_decodes(tmp_path):
    path = tmp_path / "neuron.log"
    frames = [
        nr.EnumRequest(),
        nr.EnumResponse(3),
        nr.InitialConfigRequest(3),
        nr.InitialConfig0(3, 2, True, False, 500),
        nr.InitialConfig1(3, 0, 21, 800, 0, 0),
        nr.InitialConfig2(3, 0, 2048, 0, 1200, True, False),
        nr.InitialConfig3(3, 0, 0, 0, 4096, 4096),
        *nr.pack_pwm([0, 500, 1000]),
        nr.ServoTargetAngles(3, (2048, 2000), (False, False)),
        nr.ServoTargetCurrents(3, (0, 0), (True, True)),
        nr.ServoState(3, 0, 2047, 35, False, True, False, -3, 0),
        nr.ImuFrame(3, nr.ImuMessage.GYRO, -1, 0, 1),
        nr.SetServoPidGain(3, 1, 800, 0, 0),
    ]
    writer = candump_logger(path, channel="can0")
    with open_can("virtual:rdm_log") as tx, open_can("virtual:rdm_log") as rx:
        notifier = can.Notifier(rx, [writer])
        try:
            for f in frames:
                tx.send(neuron_message(f.can_id, f.encode()))
            for _ in range(500):  # the Notifier thread writes asynchronously
                writer.file.flush()
                if len(path.read_text().splitlines()) >= len(frames):
                    break
                time.sleep(0.01)
        finally:
            notifier.stop()  # also stops (closes) the writer
    with open(path, "a") as fh:  # foreign lines a capture can contain
        fh.write("garbage line\n(1.0) can0 12345678#00 R\n(2.0) can0 7FF#\n")
    decoder = nr.NeuronDecoder()
    rows = list(nr.decode_candump(path, decoder=decoder))
    good, bad = rows[: len(frames)], rows[len(frames) :]
    assert [r["line"] for r in rows] == list(range(1, len(frames) + 4))
    assert all(r["ok"] for r in good), [r["error"] for r in good if not r["ok"]]
    assert [r["kind"] for r in good] == [f.KIND for f in frames]
    for row, f in zip(good, frames, strict=True):
        fields = f.as_dict()
        fields.pop("kind")
        assert {k: row[k] for k in fields} == fields
        assert row["id"] == f.can_id and row["data"] == f.encode().hex()
    # The PID request also reads as INITIAL_CONFIG_1 of servo index 3; the servo count learned
    # from INITIAL_CONFIG_0 (2 servos) rules that out.
    assert not any(r["ambiguous"] for r in good)
    assert decoder.ambiguous == 0
    assert [r["ok"] for r in bad] == [False, False, False]
    assert bad[0]["error"].startswith("syntax")
    assert bad[1]["error"].startswith("not_standard_id")
    assert bad[2]["error"].startswith("unknown_id")
    assert decoder.errors == {"syntax": 1, "not_standard_id": 1, "unknown_id": 1}


def test_decode_candump_asc(tmp_path):
    path = tmp_path / "neuron.asc"
    frames = [nr.ImuFrame(5, nr.ImuMessage.MAG, 7, 8, 9), nr.EnumResponse(5)]
    with can.Logger(str(path)) as writer:
        for f in frames:
            writer.on_message_received(neuron_message(f.can_id, f.encode()))
    rows = list(nr.decode_candump(path))
    assert [(r["kind"], r["ok"]) for r in rows] == [("imu", True), ("enum_response", True)]
    assert (rows[0]["x"], rows[0]["y"], rows[0]["z"], rows[0]["sensor"]) == (7, 8, 9, "mag")
    with pytest.raises(ValueError, match="unsupported log suffix"):
        list(nr.decode_candump(tmp_path / "x.blf"))
