"""Simulation logging: MCAP read back by ``mcap.reader`` and decoded by rosbags (independent
ROS1 implementation), candump read back by python-can's reader, UART captures, run folder,
metrics table / JSON summary, PNG plots."""

from __future__ import annotations

import json
import math
import uuid

import can
import numpy as np
import pytest
from mcap.reader import make_reader
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from rdm.link.inproc_can import InProcessBus, SimClock, set_channel_clock
from rdm.link.serial import open_pty_pair
from rdm.link.tapped_link import TappedLink
from rdm.protocol.rosserial.registry import spinal_registry
from rdm.sim import (
    CandumpCapture,
    McapLogger,
    Metric,
    RunFolder,
    format_metrics_table,
    ros1_definition,
    write_summary,
)
from rdm.sim.plots import plot_panels, plot_tracking_errors, plot_zmp
from rdm.sim.run_folder import RunFolderError

TYPES = ["spinal/Imu", "spinal/FourAxisCommand", "spinal/ServoStates", "spinal/PwmInfo"]


@pytest.mark.parametrize("type_name", TYPES)
def test_ros1_definition_parses_in_rosbags_with_the_ros_md5(type_name):
    reg = spinal_registry()
    text = ros1_definition(reg, type_name)
    ts = get_typestore(Stores.ROS1_NOETIC)
    pkg, name = type_name.split("/")
    ts.register(get_types_from_msg(text, f"{pkg}/msg/{name}"))
    _, md5 = ts.generate_msgdef(f"{pkg}/msg/{name}")
    assert md5 == reg.md5(type_name)


def test_mcap_round_trip_ros1_and_json(tmp_path):
    reg = spinal_registry()
    path = tmp_path / "x.mcap"
    log = McapLogger(path)
    try:
        imu = reg.msg("spinal/Imu")
        states = reg.msg("spinal/ServoStates")
        for k in range(300):
            t = k * 0.005
            log.log_ros1(
                "/imu",
                "spinal/Imu",
                t,
                imu.new(
                    acc=[0.0, 0.1, 9.8],
                    gyro=[k * 1e-3, 0, 0],
                    mag=[30, 0, -35],
                    quaternion=[0, 0, 0, 1],
                ),
            )
            if k % 10 == 0:
                msg = states.new(
                    servos=[
                        reg.msg("spinal/ServoState").new(index=i, angle=k + i) for i in range(3)
                    ]
                )
                log.log_ros1("/servo/states", "spinal/ServoStates", t, msg)
                log.log_json(
                    "/plant/x",
                    t,
                    {"pos": np.array([t, 0.0, math.nan]), "ok": True, "n": k, "nested": {"a": 1.5}},
                )
    finally:
        log.finish()
    ts = get_typestore(Stores.ROS1_NOETIC)
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        chans = {c.topic: c for c in summary.channels.values()}
        assert set(chans) == {"/imu", "/servo/states", "/plant/x"}
        for c in chans.values():
            assert c.schema_id in summary.schemas
        for topic, type_name in (("/imu", "spinal/Imu"), ("/servo/states", "spinal/ServoStates")):
            schema = summary.schemas[chans[topic].schema_id]
            assert (schema.encoding, chans[topic].message_encoding) == ("ros1msg", "ros1")
            assert chans[topic].metadata["md5sum"] == reg.md5(type_name)
            pkg, name = type_name.split("/")
            ts.register(get_types_from_msg(schema.data.decode(), f"{pkg}/msg/{name}"))
        js = summary.schemas[chans["/plant/x"].schema_id]
        assert js.encoding == "jsonschema" and json.loads(js.data)["type"] == "object"
        assert summary.statistics.message_count == 300 + 30 + 30
        counts = {"/imu": 0, "/servo/states": 0, "/plant/x": 0}
        for _s, channel, message in reader.iter_messages():
            counts[channel.topic] += 1
            if channel.topic == "/imu":
                m = ts.deserialize_ros1(message.data, "spinal/msg/Imu")
                k = counts["/imu"] - 1
                assert m.gyro[0] == pytest.approx(k * 1e-3, rel=1e-6)  # float32
                assert message.log_time == round(k * 0.005 * 1e9)
            elif channel.topic == "/servo/states":
                m = ts.deserialize_ros1(message.data, "spinal/msg/ServoStates")
                assert [s.index for s in m.servos] == [0, 1, 2]
            else:
                doc = json.loads(message.data)
                assert doc["pos"][2] is None and doc["nested"] == {"a": 1.5}
        assert counts == {"/imu": 300, "/servo/states": 30, "/plant/x": 30}


def test_mcap_refuses_type_change_and_bad_time(tmp_path):
    with McapLogger(tmp_path / "y.mcap") as log:
        log.log_ros1("/a", "spinal/Imu", 0.0, spinal_registry().msg("spinal/Imu").new())
        with pytest.raises(ValueError, match="already has type"):
            log.ros1_channel("/a", "spinal/FourAxisCommand")
        with pytest.raises(ValueError, match="time"):
            log.log_json("/b", float("nan"), {"x": 1})
    with open(tmp_path / "y.mcap", "rb") as f:
        assert make_reader(f).get_summary().statistics.message_count == 1


def test_candump_capture_of_an_inproc_channel_reads_back(tmp_path):
    name = f"cd{uuid.uuid4().hex[:16]}"
    clock = SimClock()
    set_channel_clock(name, clock)
    path = tmp_path / "can.log"
    cap = CandumpCapture(path, channel=name)
    a, b = InProcessBus(name), InProcessBus(name)
    sent = []
    try:
        for k in range(50):
            clock.set(k * 0.001)
            msg = can.Message(
                arbitration_id=0x100 + k, data=bytes([k, 255 - k]), is_extended_id=False
            )
            (a if k % 2 else b).send(msg)
            sent.append((k * 0.001, 0x100 + k, bytes([k, 255 - k])))
    finally:
        cap.close()
        a.shutdown()
        b.shutdown()
    back = [(m.timestamp, m.arbitration_id, bytes(m.data)) for m in can.LogReader(path)]
    assert back == [(pytest.approx(t, abs=1e-6), i, d) for t, i, d in sent]
    assert cap.frames == 50


def test_tapped_link_captures_exact_bytes(tmp_path):
    dev, host = open_pty_pair()
    dev.peer = None
    tap = TappedLink(dev, tmp_path / "tx.bin", tmp_path / "rx.bin")
    hl = TappedLink(host)
    from rdm.sim.pty_pair import PtyPair

    pair = PtyPair(tap, hl)
    rng = np.random.default_rng(3)
    out, inc = b"", b""
    try:
        for _ in range(40):
            chunk = rng.bytes(int(rng.integers(1, 200)))
            out += chunk
            tap.write(chunk)
            back = rng.bytes(int(rng.integers(0, 50)))
            inc += back
            hl.write(back)
            pair.settle()  # everything written is now readable on the other end
            assert hl.in_waiting == len(chunk) and tap.in_waiting == len(back)
            hl.read_available()
            tap.read_available()
    finally:
        tap.close()
        hl.close()
    assert (tmp_path / "tx.bin").read_bytes() == out
    assert (tmp_path / "rx.bin").read_bytes() == inc


def test_run_folder_layout(tmp_path):
    f = RunFolder.create("hover", base=tmp_path, seed=3)
    assert f.root == tmp_path / "hover-seed3"
    assert f.uart_dir.is_dir() and f.plots_dir.is_dir()
    assert f.plot("fig9").name == "fig9.png"
    g = RunFolder.create("hover", base=tmp_path, stamp="20260101-000000")
    assert g.root.name == "hover-20260101-000000"
    with pytest.raises(RunFolderError, match="not empty"):  # it holds its INCOMPLETE marker
        RunFolder.create("hover", base=tmp_path, seed=3)
    with pytest.raises(ValueError):
        RunFolder.create("../evil", base=tmp_path, seed=1)


def test_metrics_table_and_summary(tmp_path):
    metrics = [
        Metric("RMSE x", 0.041, 0.057, "m"),  # max rule: pass
        Metric("RMSE yaw", 0.05, 0.039, "rad"),  # fail
        Metric("thrust", 9.0, None, "N", rule="min", limit=8.0),  # pass vs limit
        Metric("mass", 3.69, 3.7, "kg", rule="near", tol=0.02),
        Metric("speed", 7.5, None, "x", rule="info"),
        Metric("nan", math.nan, 1.0, "m"),
    ]
    assert [m.passed for m in metrics] == [True, False, True, True, None, False]
    table = format_metrics_table(metrics)
    lines = table.splitlines()
    assert lines[0].split() == ["metric", "paper", "ours", "unit", "pass"]
    assert "NO" in lines[3] and "yes" in lines[2] and lines[6].rstrip().endswith("-")
    doc = write_summary(tmp_path / "s.json", metrics, seed=3, speed=np.float64(7.5))
    back = json.loads((tmp_path / "s.json").read_text())
    assert back == doc and back["all_passed"] is False and back["seed"] == 3
    assert back["metrics"][5]["ours"] is None  # NaN written as null, strict JSON


def test_plots_write_pngs(tmp_path):
    import matplotlib.image as mpimg

    t = np.linspace(0, 2, 201)
    p1 = plot_panels(
        tmp_path / "a.png",
        t,
        [("thrust", {"r1": np.sin(t), "r2": np.cos(t)}, "N"), ("q", {"q1": t}, "rad")],
        title="test",
    )
    p2 = plot_tracking_errors(
        tmp_path / "b.png", t, np.c_[t, -t, 0 * t], ["x", "y", "z"], band=0.1, ylabel="m"
    )
    zmp = np.c_[0.01 * np.sin(t), 0.02 * np.cos(t)]
    zmp[5] = np.nan
    p3 = plot_zmp(tmp_path / "c.png", zmp, (0.1, 0.15))
    for p in (p1, p2, p3):
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        img = mpimg.imread(p)
        assert img.shape[0] > 100 and img.shape[1] > 100
    with pytest.raises(ValueError):
        plot_panels(tmp_path / "d.png", t, [("x", {"bad": t[:5]}, "")])


def test_every_json_record_meets_its_channels_schema(tmp_path):
    """The schema is inferred from the first record: a field null there (no value yet) must
    not pin a type that later records break. Checked with the jsonschema package."""
    import jsonschema

    path = tmp_path / "s.mcap"
    log = McapLogger(path)
    records = [
        {"a": None, "b": 1.5, "c": [1.0, 2.0], "d": {"e": None, "f": True}},
        {"a": [1.0, 2.0], "b": None, "c": [], "d": {"e": "x", "f": False}},
        {"a": {"g": 1}, "b": float("nan"), "c": [3.0], "d": {"e": 2.5, "f": True}},
    ]
    for k, r in enumerate(records):
        log.log_json("/x", 0.1 * k, r)
    log.finish()
    with open(path, "rb") as f:
        seen = 0
        for schema, _, m in make_reader(f).iter_messages():
            assert schema.encoding == "jsonschema"
            jsonschema.validate(json.loads(m.data), json.loads(schema.data))
            seen += 1
    assert seen == 3
    assert json.loads(schema.data)["properties"]["b"] == {"type": ["number", "null"]}
