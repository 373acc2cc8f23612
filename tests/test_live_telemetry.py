"""Live telemetry (``rdm sim --live``, ``rdm onboard --live``): a Foxglove WebSocket client
(``websockets``, the ``foxglove.websocket.v1`` protocol) connects to the running command,
subscribes, decodes the binary message frames against the advertised JSON schemas and checks
them against the run's ``signals.mcap`` (read by the ``mcap`` package's reader)."""

from __future__ import annotations

import json
import math
import os
import re
import socket
import struct
import subprocess
import sys
import threading
from pathlib import Path
from typing import Any

from mcap.reader import make_reader
from websockets.exceptions import ConnectionClosed
from websockets.sync.client import connect

from rdm.sim.live import LivePublisher, LiveTee, layout_path

#: The Foxglove WebSocket protocol's names: foxglove-sdk 0.30 accepts only its present name,
#: ``foxglove.sdk.v1`` (the ops and frames of ``foxglove.websocket.v1``); a client offers both.
SUBPROTOCOLS = ["foxglove.sdk.v1", "foxglove.websocket.v1"]
TOPICS = ("/plant/ground_truth", "/onboard/status", "/onboard/signals")
#: Binary opcode of a message data frame (server to client).
MESSAGE_DATA = 0x01


def _start(args: list[str]) -> tuple[subprocess.Popen, str, list[str]]:
    """``rdm ARGS`` as a process; its ``ws://`` address from the live line on stderr, and the
    list its other stderr lines go into (drained on a thread so the pipe never fills)."""
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    proc = subprocess.Popen(
        [sys.executable, "-m", "rdm.cli", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    lines: list[str] = []
    url = None
    for line in proc.stderr:  # type: ignore[union-attr]
        lines.append(line)
        m = re.search(r"live telemetry on (ws://\S+) .*layout: (\S+)", line)
        if m:
            url = m.group(1)
            assert Path(m.group(2)) == layout_path()
            break
    assert url is not None, "".join(lines)
    threading.Thread(target=lambda: lines.extend(proc.stderr), daemon=True).start()  # type: ignore[arg-type]
    return proc, url, lines


#: Connections :func:`_client` makes at most. foxglove-sdk 0.30's server can miss a channel
#: made while a client connects and then never send it to that client (docs/sim.md, live
#: telemetry); reconnecting is the documented remedy, as for a user's Foxglove app.
CONNECTIONS = 3


def _client(url: str, topics: tuple[str, ...], per_topic: int) -> tuple[dict, dict]:
    """Subscribe to ``topics`` as they are advertised; (advertised channel per topic,
    [(log time ns, payload)] per topic) once each has ``per_topic`` messages. A connection
    on which a subscribed topic stays empty while another has ``4 * per_topic`` messages
    met the SDK's missed channel: it is closed and a fresh one made (at most CONNECTIONS)."""
    for attempt in range(1, CONNECTIONS + 1):
        result = _client_once(url, topics, per_topic, give_up=attempt < CONNECTIONS)
        if result is not None:
            return result
    raise AssertionError("unreachable")


def _client_once(
    url: str, topics: tuple[str, ...], per_topic: int, give_up: bool
) -> tuple[dict, dict] | None:
    """One connection of :func:`_client`; None when it met the missed channel and
    ``give_up`` allows another connection."""
    channels: dict[str, dict] = {}
    subs: dict[int, str] = {}
    got: dict[str, list[tuple[int, bytes]]] = {t: [] for t in topics}
    with connect(url, subprotocols=SUBPROTOCOLS, open_timeout=30) as ws:
        assert ws.subprotocol in SUBPROTOCOLS
        info = json.loads(ws.recv(timeout=30))
        assert info["op"] == "serverInfo"
        while any(len(v) < per_topic for v in got.values()):
            try:
                frame = ws.recv(timeout=60)
            except ConnectionClosed as exc:
                counts = {t: len(v) for t, v in got.items()}
                raise AssertionError(f"closed with {counts}, subscribed {subs}") from exc
            if isinstance(frame, str):
                doc = json.loads(frame)
                if doc["op"] != "advertise":
                    continue
                new = []
                for ch in doc["channels"]:
                    if ch["topic"] in topics and ch["topic"] not in channels:
                        channels[ch["topic"]] = ch
                        sub_id = len(subs) + 1
                        subs[sub_id] = ch["topic"]
                        new.append({"id": sub_id, "channelId": ch["id"]})
                if new:
                    ws.send(json.dumps({"op": "subscribe", "subscriptions": new}))
                continue
            assert frame[0] == MESSAGE_DATA
            sub_id, log_time = struct.unpack_from("<IQ", frame, 1)
            got[subs[sub_id]].append((log_time, bytes(frame[13:])))
            counts = [len(got[t]) for t in subs.values()]
            if give_up and min(counts) == 0 and max(counts) >= 4 * per_topic:
                return None
    return channels, got


def _conforms(value: Any, schema: dict) -> bool:
    """Whether ``value`` fits the JSON schema subset the MCAP logger writes (types, object
    properties, array items)."""
    kinds = schema.get("type")
    if kinds is None:
        return True
    kinds = [kinds] if isinstance(kinds, str) else kinds
    ok = {
        "boolean": isinstance(value, bool),
        "integer": isinstance(value, int) and not isinstance(value, bool),
        "number": isinstance(value, (int, float)) and not isinstance(value, bool),
        "null": value is None,
        "string": isinstance(value, str),
        "array": isinstance(value, list),
        "object": isinstance(value, dict),
    }
    if not any(ok.get(k, False) for k in kinds):
        return False
    if isinstance(value, dict):
        props = schema.get("properties", {})
        return set(value) == set(props) and all(_conforms(value[k], props[k]) for k in value)
    if isinstance(value, list):
        items = schema.get("items", {})
        return all(_conforms(v, items) for v in value)
    return True


def test_rdm_sim_live_serves_the_mcap_channels_and_records(tmp_path) -> None:
    proc, url, lines = _start(
        [
            "sim",
            "hover",
            "--duration",
            "3",
            "--speed",
            "realtime",
            "--out",
            str(tmp_path),
            "--live",
            "--live-port",
            "0",
        ]
    )
    try:
        channels, got = _client(url, TOPICS, per_topic=5)
        # the client has gone: the run goes on and ends as without it
        assert proc.wait(timeout=300) in (0, 1), "".join(lines)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert "Traceback" not in "".join(lines)
    with open(tmp_path / "hover-seed0" / "signals.mcap", "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None
        by_topic = {c.topic: c for c in summary.channels.values()}
        recorded: dict[tuple[str, int], bytes] = {}
        for _schema, channel, message in reader.iter_messages(topics=list(TOPICS)):
            recorded[(channel.topic, message.log_time)] = message.data
    for topic in TOPICS:
        ch, mc = channels[topic], by_topic[topic]
        schema = summary.schemas[mc.schema_id]
        # one schema set serves the live view and the file
        assert (ch["encoding"], ch["schemaEncoding"]) == (mc.message_encoding, schema.encoding)
        assert ch["schemaName"] == schema.name
        assert json.loads(ch["schema"]) == json.loads(schema.data)
        for log_time, payload in got[topic]:
            live = json.loads(payload)
            if topic == "/plant/ground_truth":
                # (the status and signals schemas are inferred from a first record whose
                # empty fields are null: "number or null" where later records hold arrays
                # and strings; the file carries the same schema)
                assert _conforms(live, json.loads(ch["schema"])), (topic, live)
            # the record the file holds at the same time, value for value
            assert live == json.loads(recorded[(topic, log_time)]), (topic, log_time)
    for log_time, payload in got["/plant/ground_truth"]:
        truth = json.loads(payload)
        assert log_time == round(truth["time"] * 1e9)
        assert math.isclose(math.hypot(*truth["base_quaternion"]), 1.0, abs_tol=1e-9)
    for _, payload in got["/onboard/status"]:
        assert len(json.loads(payload)["duties"]) in (0, 4)  # empty until Spinal runs


def _busy_port() -> socket.socket:
    s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    s.bind(("127.0.0.1", 0))
    s.listen()
    return s


def test_live_on_a_busy_port_exits_2_naming_the_port(tmp_path) -> None:
    with _busy_port() as s:
        port = s.getsockname()[1]
        for args in (
            ["sim", "hover", "--duration", "0.5", "--out", str(tmp_path)],
            ["onboard", "--no-record", "--uart", "pty", "--foot-sensor", "none"],
        ):
            out = subprocess.run(
                [sys.executable, "-m", "rdm.cli", *args, "--live", "--live-port", str(port)],
                capture_output=True,
                text=True,
                timeout=120,
            )
            assert out.returncode == 2, out.stderr
            err = out.stderr.strip().splitlines()
            assert len(err) == 1 and f"--live-port {port}" in err[0], out.stderr
            assert "Traceback" not in out.stderr
    assert not (tmp_path / "hover-seed0").exists()


def test_rdm_onboard_live_serves_the_node_status(tmp_path) -> None:
    proc, url, lines = _start(
        [
            "onboard",
            "--no-record",
            "--uart",
            "pty",
            "--foot-sensor",
            "none",
            "--duration",
            "30",
            "--live",
            "--live-port",
            "0",
        ]
    )
    try:
        channels, got = _client(url, ("/onboard/status", "/onboard/signals"), per_topic=3)
        # a client that leaves changes nothing: a second one is served the same channels
        again, _ = _client(url, ("/onboard/status",), per_topic=1)
        assert again["/onboard/status"]["schema"] == channels["/onboard/status"]["schema"]
    finally:
        proc.terminate()
        proc.wait(timeout=60)
    assert proc.returncode == 0, "".join(lines)
    times = []
    for log_time, payload in got["/onboard/status"]:
        status = json.loads(payload)
        assert status["flight_state"] == "idle" and status["perching"] is False
        assert log_time == round(status["time"] * 1e9)
        times.append(log_time)
    assert times == sorted(times) and len(set(times)) == len(times)
    for _, payload in got["/onboard/signals"]:
        signals = json.loads(payload)
        assert signals["foot_wrench"] is None and signals["imu_euler"] is None


def test_a_failing_publisher_never_reaches_the_run() -> None:
    calls: list[tuple] = []

    class File:
        def log_json(self, *a: Any) -> None:
            calls.append(a)

        def finish(self) -> None:
            calls.append(("finish",))

    class Broken:
        def log_json(self, *a: Any) -> None:
            raise OSError("gone")

    tee = LiveTee(File(), Broken())  # type: ignore[arg-type]
    tee.log_json("/a", 0.0, {"x": 1.0})
    tee.log_json("/a", 0.1, {"x": 2.0})
    tee.finish()
    assert calls == [("/a", 0.0, {"x": 1.0}), ("/a", 0.1, {"x": 2.0}), ("finish",)]
    assert tee.live_errors == 1 and tee.live is None


def test_nothing_is_encoded_without_a_subscriber() -> None:
    live = LivePublisher(port=0)
    try:
        assert live.wants("/a")
        live.log_json("/a", 0.0, {"x": 1.0})  # advertises the channel
        assert not live.wants("/a")
        live.log_json("/a", 0.1, {"x": float("nan")})
        assert live.published == 0
    finally:
        live.close()
    assert not live.wants("/b")


def test_the_layout_plots_channels_the_run_carries() -> None:
    layout = json.loads(layout_path().read_text())
    fields = {
        "/plant/ground_truth": {"base_quaternion", "base_position", "foot_contact_force"},
        "/onboard/signals": {"imu_euler", "mocap_position", "foot_wrench"},
        "/onboard/status": {"duties", "state", "perch_status"},
    }
    paths = {
        p["value"].split("[")[0] for cfg in layout["configById"].values() for p in cfg["paths"]
    }
    for topic, names in fields.items():
        assert {f"{topic}.{n}" for n in names} <= paths
    panels = set(layout["configById"])
    assert any(p.startswith("StateTransitions!") for p in panels)


def test_live_without_the_sim_extra_names_the_install_line(monkeypatch, capsys) -> None:
    import argparse

    from rdm.commands import live as live_cmd

    real = live_cmd.importlib.util.find_spec
    monkeypatch.setattr(
        live_cmd.importlib.util,
        "find_spec",
        lambda name, *a: None if name == "foxglove" else real(name, *a),
    )
    args = argparse.Namespace(live=True, live_host="127.0.0.1", live_port=0)
    assert live_cmd.open_live(args, "rdm onboard") is False
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert line.startswith("rdm onboard: --live needs the simulator extra")
    assert 'pip install "rdm[sim]"' in line
    assert live_cmd.open_live(argparse.Namespace(live=False), "rdm onboard") is None
