"""Every wire message of a run in one MCAP (``rdm decode RUN --mcap``): complete against the
decoders, timed against python-can's reading of the candump log, rosserial's time sync and the
Leptrino stream rate, payloads decoded by rosbags (an independent ROS1 implementation)."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from collections import Counter

import can
import numpy as np
import pytest
from mcap.reader import make_reader
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from rdm.link.capture_index import index_path
from rdm.protocol.leptrino import decode_leptrino
from rdm.protocol.neuron import decode_candump
from rdm.protocol.rosserial.capture import decode_uart, load_layout
from rdm.scenarios.common import run_stack, sim_stack_options
from rdm.scenarios.hover import HOVER_Z, make_script
from rdm.scenarios.stack import build_stack
from rdm.sim.wire_mcap import WireMcapError, run_captures, write_wire_mcap

SECONDS = 3.0


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """A 3 s hover run's folder, its wire MCAP and the conversion's report."""
    base = tmp_path_factory.mktemp("wire")
    opts = sim_stack_options(0, "inproc", log=True)
    stack = build_stack("wire", base, opts, make_script(np.array([0.483, 0.0, HOVER_Z])))
    run_stack(stack, SECONDS)
    folder = stack.folder.root
    out = base / "wire.mcap"
    report = write_wire_mcap(run_captures(folder), out)
    return folder, out, report, opts


def _messages(path, prefix=""):
    """(topic, schema, log_time, data) of every message, in the file's time order."""
    with open(path, "rb") as f:
        return [
            (ch.topic, schema, m.log_time, m.data)
            for schema, ch, m in make_reader(f).iter_messages(log_time_order=True)
            if ch.topic.startswith(prefix)
        ]


class _Ros1:
    """rosbags' ROS1 deserialiser fed with the schemas the MCAP carries."""

    def __init__(self) -> None:
        self.store = get_typestore(Stores.ROS1_NOETIC)
        self.known: set[str] = set()

    def __call__(self, schema, data):
        pkg, name = schema.name.split("/")
        key = f"{pkg}/msg/{name}"
        if key not in self.known:
            self.store.register(get_types_from_msg(schema.data.decode(), key))
            self.known.add(key)
        return self.store.deserialize_ros1(data, key)


def test_every_decoded_record_is_one_message(run):
    folder, out, report, _ = run
    with open(out, "rb") as f:
        summary = make_reader(f).get_summary()
    counts = {
        summary.channels[cid].topic: n
        for cid, n in summary.statistics.channel_message_counts.items()
    }
    assert counts == dict(report.messages)
    assert not report.skipped and not report.errors
    expected = Counter()
    expected["can"] = sum(1 for _ in decode_candump(folder / "can.log"))
    for side in ("device_tx", "host_tx"):
        data = (folder / "uart" / f"spinal.{side}.bin").read_bytes()
        expected[f"spinal/{side}"] = sum(1 for _ in decode_uart(data, layout=load_layout()))
        lep = (folder / "uart" / f"leptrino_foot.{side}.lep").read_bytes()
        expected[f"leptrino_foot/{side}"] = sum(
            1 for _ in decode_leptrino(lep, from_sensor=side == "device_tx")
        )
    got = Counter()
    for topic, n in counts.items():
        parts = topic.split("/")
        got["can" if parts[2] == "can" else f"{parts[2]}/{parts[3]}"] += n
    assert got == expected
    assert expected["can"] > 3000 and expected["spinal/device_tx"] > 600


def test_can_frames_at_their_candump_times_as_python_can_reads_them(run):
    folder, out, _, _ = run
    with can.CanutilsLogReader(str(folder / "can.log")) as reader:
        theirs = Counter(
            (round(m.timestamp * 1e6), m.arbitration_id, bytes(m.data).hex()) for m in reader
        )
    ours = Counter()
    for _topic, _schema, log_time, data in _messages(out, "/wire/can/"):
        rec = json.loads(data)
        assert log_time % 1000 == 0
        ours[(log_time // 1000, rec["id"], rec["data"])] += 1
    assert ours == theirs


def test_spinal_stamps_follow_rosserials_time_sync_from_the_index(run):
    """rosserial's client sets its clock to the host's time plus the whole round trip of the
    request, so a message's stamp runs ahead of the wire time by (host's time - request
    time) of the last sync Spinal received, and 0 before the first (Spinal boots at 0)."""
    _, out, _, _ = run
    ros1 = _Ros1()
    requests, responses, stamped = [], [], []
    for topic, schema, log_time, data in _messages(out, "/wire/spinal/"):
        if topic == "/wire/spinal/device_tx/rosserial/time":
            requests.append(log_time)
        elif topic == "/wire/spinal/host_tx/rosserial/time":
            t = ros1(schema, data).data
            responses.append((log_time, t.sec * 10**9 + t.nanosec))
        elif topic in ("/wire/spinal/device_tx/imu", "/wire/spinal/device_tx/servo/states"):
            s = ros1(schema, data).stamp
            stamped.append((topic, log_time, s.sec * 10**9 + s.nanosec))
    assert len(requests) == len(responses) >= 2
    syncs = [
        (received, host - asked)
        for asked, (received, host) in zip(requests, responses, strict=True)
    ]
    assert all(ahead > 0 for _, ahead in syncs)  # the 40 Hz host answers a tick later
    imu_times = [t for topic, t, _ in stamped if topic.endswith("imu")]
    assert len(imu_times) > 500
    assert set(np.diff(imu_times)) == {5_000_000}  # 200 Hz, each at its own tick
    for _topic, log_time, stamp in stamped:
        ahead = 0
        for received, offset in syncs:
            if received <= log_time:
                ahead = offset
        assert stamp - log_time == ahead


def test_leptrino_frames_at_the_sensor_rate(run):
    _, out, _, opts = run
    times = [t for _, _, t, _ in _messages(out, "/wire/leptrino_foot/device_tx/force_data")]
    assert len(times) >= SECONDS * opts.leptrino_rate_hz - 2
    assert set(np.diff(times)) == {round(1e9 / opts.leptrino_rate_hz)}


def test_ros1_payloads_decode_in_rosbags_as_on_the_wire(run):
    folder, out, _, _ = run
    ros1 = _Ros1()
    ours = [
        rec
        for rec in decode_uart(
            (folder / "uart" / "spinal.device_tx.bin").read_bytes(), layout=load_layout()
        )
        if rec.get("topic") == "imu"
    ]
    theirs = [
        ros1(schema, data)
        for topic, schema, _, data in _messages(out, "/wire/spinal/device_tx/imu")
        if topic == "/wire/spinal/device_tx/imu"  # not imu_calib
    ]
    assert len(ours) == len(theirs) > 500
    for rec, msg in zip(ours, theirs, strict=True):
        f = rec["fields"]
        assert list(msg.quaternion) == f["quaternion"]
        assert list(msg.gyro) == f["gyro"] and list(msg.acc) == f["acc"]
    # every ROS1 channel (handshake, services, commands) is valid ROS1 for rosbags
    types = set()
    for _topic, schema, _, data in _messages(out, "/wire/"):
        if schema.encoding == "ros1msg":
            types.add(type(ros1(schema, data)).__name__)
    assert {"spinal__msg__FourAxisCommand", "rosserial_msgs__msg__TopicInfo"} <= types
    assert len(types) >= 15


def test_bad_bytes_go_to_the_errors_channel(run, tmp_path):
    folder, _, report, _ = run
    src = folder / "uart" / "spinal.device_tx.bin"
    capture = tmp_path / src.name
    data = bytearray(src.read_bytes())
    data[len(data) // 2] ^= 0xFF  # one byte of one frame: its checksum fails
    capture.write_bytes(bytes(data))
    shutil.copy(index_path(src), index_path(capture))
    bad = write_wire_mcap([capture], tmp_path / "bad.mcap")
    assert bad.errors[capture.name] >= 1
    errors = _messages(tmp_path / "bad.mcap", "/wire/spinal/device_tx/errors")
    assert len(errors) == sum(bad.errors.values())
    assert "error" in json.loads(errors[0][3])
    good = sum(n for t, n in report.messages.items() if t.startswith("/wire/spinal/device_tx"))
    kept = sum(n for t, n in bad.messages.items() if not t.endswith("/errors"))
    assert good - 2 <= kept < good  # the frame hit (and at most its neighbour) is lost


def test_a_killed_runs_capture_and_index_keep_every_message(run, tmp_path):
    """A run killed before it closed its files: the capture and its index each lost their own
    unwritten tail. Every message is kept; those past the index take its last time."""
    folder, _, report, _ = run
    src = folder / "uart" / "spinal.device_tx.bin"
    full = src.read_bytes()
    whole = report.messages["/wire/spinal/device_tx/imu"]
    # the capture lost more: its last frame is cut (an error record), the rest timed
    short = tmp_path / "a" / src.name
    short.parent.mkdir()
    short.write_bytes(full[:-3])
    shutil.copy(index_path(src), index_path(short))
    r = write_wire_mcap([short], tmp_path / "a.mcap")
    assert r.partial == [(short, len(full), len(full) - 3)]
    assert r.errors[short.name] == 1  # the cut frame
    assert whole - 1 <= r.messages["/wire/spinal/device_tx/imu"] <= whole
    # the index lost more: the frames past it are kept, at its last entry's time
    long_ = tmp_path / "b" / src.name
    long_.parent.mkdir()
    long_.write_bytes(full)
    index = index_path(src).read_bytes()
    index_path(long_).write_bytes(index[: len(index) - 16 * 40])  # 40 writes of the tail
    r = write_wire_mcap([long_], tmp_path / "b.mcap")
    assert r.partial and r.partial[0][2] == len(full) and not r.errors
    assert r.messages == Counter(
        {t: n for t, n in report.messages.items() if t.startswith("/wire/spinal/device_tx/")}
    )
    times = [t for _, _, t, _ in _messages(tmp_path / "b.mcap", "/wire/spinal/device_tx/imu")]
    assert times == sorted(times) and times.count(times[-1]) > 5  # the tail at one time
    cli = [sys.executable, "-m", "rdm.cli", "decode", str(long_), "--mcap"]
    out = subprocess.run([*cli, str(tmp_path / "c.mcap")], capture_output=True, text=True)
    assert out.returncode == 0 and "its index covers" in out.stderr


def test_an_index_that_is_not_one_is_refused(run, tmp_path):
    folder, _, _, _ = run
    src = folder / "uart" / "spinal.device_tx.bin"
    capture = tmp_path / src.name
    shutil.copy(src, capture)
    index = bytearray(index_path(src).read_bytes())
    index[8 + 16 * 3 : 8 + 16 * 3 + 8] = (2**62).to_bytes(8, "little")  # a time far ahead
    index_path(capture).write_bytes(bytes(index))
    with pytest.raises(WireMcapError, match="goes back in time"):
        write_wire_mcap([capture], tmp_path / "no.mcap")
    assert not (tmp_path / "no.mcap").exists()  # nothing written
    cli = [sys.executable, "-m", "rdm.cli", "decode", str(capture), "--mcap"]
    r = subprocess.run([*cli, str(tmp_path / "no.mcap")], capture_output=True, text=True)
    assert r.returncode == 2 and "goes back in time" in r.stderr and "Traceback" not in r.stderr


def test_rdm_decode_mcap_of_a_run_folder(run, tmp_path):
    folder, _, report, _ = run
    out = tmp_path / "cli.mcap"
    r = subprocess.run(
        [sys.executable, "-m", "rdm.cli", "decode", str(folder), "--mcap", str(out)],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 0, r.stderr
    assert f"{report.total} messages on {len(report.messages)} channels" in r.stderr
    assert "/wire/spinal/device_tx/imu" in r.stdout
    # a capture without its index is left out of a folder and named
    (folder / "uart" / "spinal.host_tx.bin.idx").rename(tmp_path / "kept.idx")
    try:
        r = subprocess.run(
            [sys.executable, "-m", "rdm.cli", "decode", str(folder), "--mcap", str(out)],
            capture_output=True,
            text=True,
        )
    finally:
        (tmp_path / "kept.idx").rename(folder / "uart" / "spinal.host_tx.bin.idx")
    assert r.returncode == 0
    assert "left out" in r.stderr and "spinal.host_tx.bin" in r.stderr
    assert "/wire/spinal/host_tx/" not in r.stdout


def _repeated_capture(src, dest, times: int) -> int:
    """``src``'s bytes ``times`` over into ``dest``, timed 1 ms per 512-byte write."""
    from rdm.link.capture_index import TimedCaptureFile

    data = src.read_bytes()
    t = [0.0]
    out = TimedCaptureFile(dest, lambda: t[0])
    for _ in range(times):
        for i in range(0, len(data), 512):
            out.write(data[i : i + 512])
            t[0] += 1e-3
    out.close()
    return len(data) * times


def test_memory_does_not_grow_with_the_capture(run, tmp_path):
    """A capture 40 times the run's is converted with Python allocations far below its size
    (tracemalloc's peak): the capture is read in chunks and its messages written as they are
    decoded, not gathered first (which peaks near ten times the capture)."""
    import tracemalloc

    folder, _, report, _ = run
    capture = tmp_path / "spinal.device_tx.bin"
    size = _repeated_capture(folder / "uart" / capture.name, capture, 40)
    assert size > 1_000_000
    tracemalloc.start()
    try:
        big = write_wire_mcap([capture], tmp_path / "big.mcap")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert big.total == 40 * sum(
        n for t, n in report.messages.items() if t.startswith("/wire/spinal/device_tx/")
    )
    assert peak < size / 2, f"peak {peak} B for a {size} B capture"


def test_captures_merge_in_time_order_and_a_step_back_is_counted(run, tmp_path):
    """Two captures interleave by time in the file (equal times: the captures' order); a
    candump line stamped earlier than the one before it is still written at its own time and
    counted in the report and its warnings."""
    folder, _, _, _ = run
    lines = (folder / "can.log").read_text().splitlines(keepends=True)
    stamp = lambda line: float(line[1 : line.index(")")])  # noqa: E731
    i = len(lines) // 2
    moved = lines[i].replace(f"({lines[i][1 : lines[i].index(')')]})", f"({stamp(lines[1]):.6f})")
    assert stamp(moved) < stamp(lines[i - 1])
    can_log = tmp_path / "can.log"
    can_log.write_text("".join([*lines[:i], moved, *lines[i + 1 :]]))
    uart = folder / "uart" / "spinal.device_tx.bin"
    r = write_wire_mcap([can_log, uart], tmp_path / "m.mcap")
    assert r.out_of_order == Counter({"can.log": 1})
    assert any("can.log: 1 messages earlier" in w for w in r.warnings())
    with open(tmp_path / "m.mcap", "rb") as f:
        in_file = [
            (ch.topic, m.log_time)
            for _, ch, m in make_reader(f).iter_messages(log_time_order=False)
        ]
    times = [t for _, t in in_file]
    back = [k for k in range(1, len(times)) if times[k] < times[k - 1]]
    assert len(back) == 1 and in_file[back[0]][1] == round(stamp(lines[1]) * 1e9)
    rest = times[: back[0]] + times[back[0] + 1 :]
    assert rest == sorted(rest)  # merged by time: both wires interleaved
    topics = {t.split("/")[2] for t, _ in in_file[: len(in_file) // 2]}
    assert topics == {"can", "spinal"}


def test_the_runs_signal_records_meet_their_schemas(run):
    """Every JSON record of the run's ``signals.mcap`` (ground truth, the onboard PC's status
    and signals) validates against its channel's schema (jsonschema)."""
    import jsonschema

    folder, _, _, _ = run
    counts: Counter[str] = Counter()
    validators: dict[int, jsonschema.protocols.Validator] = {}
    with open(folder / "signals.mcap", "rb") as f:
        for schema, ch, m in make_reader(f).iter_messages():
            if schema.encoding != "jsonschema":
                continue
            if schema.id not in validators:
                validators[schema.id] = jsonschema.Draft202012Validator(json.loads(schema.data))
            validators[schema.id].validate(json.loads(m.data))
            counts[ch.topic] += 1
    assert {"/plant/ground_truth", "/onboard/status", "/onboard/signals"} <= set(counts)
