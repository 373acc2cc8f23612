"""Client (Spinal) and server (PC) state machines in lockstep, over a real pty pair with pyserial
on both ends, driven by explicit time."""

from __future__ import annotations

import itertools
import json
import shutil
import time
from pathlib import Path

import pytest

from rdm.link.serial import open_pty_pair
from rdm.protocol.rosserial import constants as C
from rdm.protocol.rosserial.client import ClientSession
from rdm.protocol.rosserial.codec import RosTime
from rdm.protocol.rosserial.events import (
    Configured,
    DroppedMessage,
    FrameRejected,
    LogReceived,
    MessageReceived,
    ServiceHandled,
    ServiceReady,
    ServiceResponse,
    ServiceTimeout,
    SyncLost,
    TimeSynced,
    TopicRefused,
    TopicRegistered,
)
from rdm.protocol.rosserial.framing import Frame, FrameParser, encode_frame
from rdm.protocol.rosserial.registry import TypeRegistry, spinal_registry
from rdm.protocol.rosserial.server import PayloadTooLarge, ServerSession, TopicNotNegotiated
from rdm.protocol.rosserial.services import ServiceError

SPINAL = Path(__file__).resolve().parents[1] / "firmware_protocol" / "spinal"
GOLDEN = json.loads((SPINAL / "golden_frames.json").read_text())
REG = spinal_registry()
EPOCH_NS = 1_767_225_600 * 10**9  # the PC's ROS time at now = 0


def pc_time(now: float) -> RosTime:
    return RosTime.from_ns(EPOCH_NS + round(now * 1e9))


def read_exact(link, n: int, timeout: float = 2.0) -> bytes:
    """Read exactly n bytes that the peer wrote (the pty delivers asynchronously)."""
    data = b""
    deadline = time.monotonic() + timeout
    while len(data) < n and time.monotonic() < deadline:
        data += link.read_available()
        if len(data) < n:
            time.sleep(0.0005)
    assert len(data) == n, f"expected {n} bytes, got {len(data)}"
    return data


class Lockstep:
    """Steps both roles at explicit times; bytes cross a pty pair (or memory)."""

    def __init__(self, client: ClientSession, server: ServerSession, pty: bool = True) -> None:
        self.client, self.server = client, server
        self.links = open_pty_pair() if pty else None  # (device side, PC side)
        self.client_events: list = []
        self.server_events: list = []
        self.to_client: list[tuple[int, bytes]] = []  # (tick, bytes) the client received
        self.to_server: list[tuple[int, bytes]] = []
        self.cut = False  # True: the wire is broken, nothing arrives
        self.tick_offset = 0  # the MCU tick = (now_ms + tick_offset) mod 2**32

    def _cross(self, data: bytes, toward_client: bool) -> bytes:
        if self.cut:
            return b""
        if self.links is None or not data:
            return data
        dev, pc = self.links
        src, dst = (pc, dev) if toward_client else (dev, pc)
        src.write(data)
        return read_exact(dst, len(data))

    def step(self, now_ms: int) -> None:
        down = self._cross(self.server.take_output(), toward_client=True)
        self.to_client.append((now_ms, down))
        tick = (now_ms + self.tick_offset) & 0xFFFFFFFF
        self.client_events += [(now_ms, e) for e in self.client.spin(down, tick)]
        up = self._cross(self.client.take_output(), toward_client=False)
        self.to_server.append((now_ms, up))
        self.server_events += [(now_ms, e) for e in self.server.feed(up, now_ms / 1000)]

    def run(self, start_ms: int, stop_ms: int, dt_ms: int) -> None:
        for t in range(start_ms, stop_ms, dt_ms):
            self.step(t)

    def close(self) -> None:
        if self.links:
            self.links[0].close()

    def events(self, side: str, kind: type) -> list:
        evs = self.client_events if side == "client" else self.server_events
        return [(t, e) for t, e in evs if isinstance(e, kind)]


def frames_of(chunks) -> list[tuple[int, Frame]]:
    parser = FrameParser(1022)
    out = []
    for t, data in chunks:
        out += [(t, f) for f in parser.feed(data) if isinstance(f, Frame)]
    return out


@pytest.fixture
def link():
    ls = Lockstep(ClientSession.from_layout(), ServerSession(time_source=pc_time))
    yield ls
    ls.close()


def handshake(ls: Lockstep, t0: int = 1000) -> None:
    ls.server.start(t0 / 1000)
    ls.run(t0, t0 + 30, 10)


def test_handshake_over_pty_matches_golden_bytes(link):
    handshake(link)
    assert link.to_client[0][1].hex() == GOLDEN["handshake"]["server_request"]
    golden = b"".join(bytes.fromhex(v["hex"]) for v in GOLDEN["handshake"]["client_reply"])
    assert link.to_server[0][1] == golden  # time request + 16 publishers + 21 subscribers
    assert link.client.configured
    assert len(link.events("client", Configured)) == 1
    registered = [e for _, e in link.events("server", TopicRegistered)]
    assert len(registered) == 37
    assert not link.events("server", TopicRefused)
    assert [e.topic_id for e in registered[:16]] == list(range(150, 166))
    assert [e.topic_id for e in registered[16:]] == list(range(100, 121))
    assert {e.service for _, e in link.events("server", ServiceReady)} == {
        "imu_calib",
        "mag_declination",
        "set_attitude_control",
        "get_board_info",
        "set_board_config",
    }
    assert link.server.outbound["four_axes/command"].topic_id == 108
    assert link.server.inbound[153].name == "imu"


def test_time_sync_over_pty(link):
    handshake(link)
    synced = link.events("client", TimeSynced)
    assert len(synced) == 1
    t_sync, ev = synced[0]
    assert ev.round_trip_ms == 10  # request at 1000 ms, answer read at the next step
    # the client's ROS time follows the PC's to the millisecond from then on
    for t in (t_sync, t_sync + 1, t_sync + 777, t_sync + 5000):
        assert abs(link.client.now(t).to_ns() - pc_time(t / 1000).to_ns()) <= 1_000_000


def test_time_sync_with_an_mcu_tick_that_wraps(link):
    # the MCU booted long ago: its uint32 ms tick wraps 3 s after the handshake
    link.tick_offset = 2**32 - 4000
    handshake(link)
    link.run(1030, 9000, 50)
    ups = frames_of(link.to_server)
    requests = [t for t, f in ups if f.topic_id == C.TopicId.TIME]
    gaps = [b - a for a, b in itertools.pairwise(requests[1:])]
    assert gaps and all(2500 < g <= 2550 for g in gaps), gaps
    assert not link.events("client", SyncLost) and link.client.configured
    for t in (3000, 3999, 4000, 5000, 8999):  # before and after the wrap
        tick = (t + link.tick_offset) & 0xFFFFFFFF
        assert abs(link.client.now(tick).to_ns() - pc_time(t / 1000).to_ns()) <= 1_000_000


def test_time_requests_every_2500ms_and_loss_after_11s(link):
    handshake(link)
    link.run(1030, 12_000, 50)
    ups = frames_of(link.to_server)
    requests = [t for t, f in ups if f.topic_id == C.TopicId.TIME]
    gaps = [b - a for a, b in itertools.pairwise(requests[1:])]
    assert gaps and all(2500 < g <= 2550 for g in gaps), gaps
    assert len(link.events("client", TimeSynced)) == len(requests)
    # the PC stops answering: the wire breaks after the last answer at t_last
    link.cut = True
    t_last = link.events("client", TimeSynced)[-1][0]
    link.run(12_000, t_last + 11_000 + 200, 10)
    lost = link.events("client", SyncLost)
    assert len(lost) == 1
    assert t_last + 11_000 < lost[0][0] <= t_last + 11_010
    assert not link.client.configured
    imu = REG.msg("spinal/Imu")
    assert link.client.publish("imu", imu.new()) == 0  # user topics stop
    assert link.client.counts["tx_not_configured"] == 1
    # the PC side has lost sync too (5 s) and re-opens 2 s later: a new handshake follows
    assert link.events("server", SyncLost)
    link.cut = False
    link.run(t_last + 11_200, t_last + 15_000, 10)
    assert link.client.configured
    assert len(link.events("client", Configured)) >= 2


def test_server_reports_loss_when_device_is_silent():
    server = ServerSession(time_source=pc_time)
    server.start(0.0)
    assert server.take_output() == bytes.fromhex("fffe0000ff0000ff")
    assert server.poll(1.0) == []
    assert isinstance(server.poll(1.001)[0], SyncLost)
    assert not server.active
    assert server.poll(2.9) == [] and server.take_output() == b""
    server.poll(3.001)  # re-open after 2 s: a new topic request
    assert server.active and server.take_output() == bytes.fromhex("fffe0000ff0000ff")


def test_topics_both_ways_and_log(link):
    handshake(link)
    cmd = REG.msg("spinal/FourAxisCommand")
    link.server.publish(
        "four_axes/command", cmd.new(angles=[0.1, -0.2, 0.3], base_thrust=[5.5] * 4)
    )
    imu = REG.msg("spinal/Imu")
    sample = imu.new(stamp=link.client.now(1040), quaternion=[0.0, 0.0, 0.0, 1.0])
    assert link.client.publish("imu", sample) > 0
    link.client.log(C.LogLevel.WARN, "low battery")
    link.step(1040)
    (_, got) = link.events("client", MessageReceived)[0]
    assert got.topic == "four_axes/command" and got.topic_id == 108
    assert got.message.base_thrust == [5.5] * 4
    assert got.message.angles[1] == pytest.approx(-0.2, abs=1e-7)
    (_, up) = link.events("server", MessageReceived)[0]
    assert up.topic == "imu" and up.message == sample
    assert [e for _, e in link.events("server", LogReceived)] == [LogReceived(2, "low battery")]


def test_services_round_trip(link):
    seen = []

    def mag(req):
        seen.append(req)
        res = REG.srv("spinal/MagDeclination").response
        return res.new(success=True, data=req.data * 2)

    link.client = ClientSession.from_layout(handlers={"mag_declination": mag})
    handshake(link)
    req = REG.srv("spinal/MagDeclination").request.new(command=1, data=0.25)
    call = link.server.call_service("mag_declination", req, 1.03)
    with pytest.raises(ServiceError, match="pending"):
        link.server.call_service("mag_declination", req, 1.03)
    link.step(1040)
    assert seen == [req]
    (_, handled) = link.events("client", ServiceHandled)[0]
    assert handled.service == "mag_declination"
    (_, res) = link.events("server", ServiceResponse)[0]
    assert res.call_id == call and res.response.success and res.response.data == 0.5
    # a service with a string in its response, and one with nested arrays
    board = REG.msg("spinal/BoardInfo")
    boards = [board.new(slave_id=i, servos=[REG.msg("spinal/ServoInfo").new(id=7)]) for i in (1, 2)]
    link.client.subscribers[119 - 100].service.handler = lambda _r: REG.srv(
        "spinal/GetBoardInfo"
    ).response.new(boards=boards)
    link.server.call_service("get_board_info", REG.srv("spinal/GetBoardInfo").request.new(), 1.05)
    link.server.call_service(
        "set_attitude_control", REG.srv("std_srvs/SetBool").request.new(data=True), 1.05
    )
    link.step(1060)
    responses = {e.service: e.response for _, e in link.events("server", ServiceResponse)}
    assert responses["get_board_info"].boards == boards
    assert responses["set_attitude_control"].message == ""
    with pytest.raises(ServiceError, match="not"):
        link.server.call_service("no_such_service", req, 1.1)


def test_faulty_service_handler_is_contained(link):
    link.client = ClientSession.from_layout(handlers={"imu_calib": lambda req: 1 / 0})
    handshake(link)
    link.server.call_service("imu_calib", REG.srv("spinal/ImuCalib").request.new(), 1.03)
    link.step(1040)
    (_, dropped) = link.events("client", DroppedMessage)[0]
    assert dropped.topic_id == 100 and "ZeroDivisionError" in dropped.reason
    assert link.client.counts["rx_dropped"] == 1 and link.client.configured


def test_service_timeout_after_10s(link):
    handshake(link)
    req = REG.srv("spinal/ImuCalib").request.new(command=0)
    call = link.server.call_service("imu_calib", req, 1.03)
    link.server.take_output()  # the request is lost on the wire; time sync goes on
    link.run(1030, 11_100, 10)
    timeouts = link.events("server", ServiceTimeout)
    assert timeouts == [(11_040, ServiceTimeout("imu_calib", call))]
    assert not link.events("server", ServiceResponse)
    assert not link.events("server", SyncLost)


def tampered_registry(tmp_path: Path, rel: str, old: str, new: str) -> TypeRegistry:
    root = tmp_path / "msgs"
    shutil.copytree(SPINAL, root, ignore=shutil.ignore_patterns("tools", "*.json"))
    path = root / rel
    path.write_text(path.read_text().replace(old, new))
    return TypeRegistry.from_directory(root)


def test_server_refuses_topics_whose_md5_differs(tmp_path):
    # the device was built from an older FourAxisCommand and Imu: same names, other layouts
    reg = tampered_registry(tmp_path, "spinal/msg/FourAxisCommand.msg", "float32[3]", "float32[4]")
    imu_path = tmp_path / "msgs" / "spinal" / "msg" / "Imu.msg"
    imu_path.write_text(imu_path.read_text().replace("float32[3] mag", "int16[3] mag"))
    reg = TypeRegistry.from_directory(tmp_path / "msgs")
    ls = Lockstep(ClientSession.from_layout(registry=reg), ServerSession(time_source=pc_time))
    try:
        handshake(ls)
        refused = {e.topic: e for _, e in ls.events("server", TopicRefused)}
        assert set(refused) == {"four_axes/command", "imu"}
        assert refused["imu"].md5 == reg.md5("spinal/Imu")
        assert refused["imu"].expected_md5 == "ae078a6cf2a27bba55c15c4ea83c6817"
        assert ls.server.counts["topic_refused"] == 2
        with pytest.raises(TopicNotNegotiated):
            ls.server.publish("four_axes/command", REG.msg("spinal/FourAxisCommand").new())
        ls.client.publish("imu", reg.msg("spinal/Imu").new())
        ls.step(1040)
        assert not ls.events("server", MessageReceived)  # never decoded with a wrong layout
        (_, dropped) = ls.events("server", DroppedMessage)[0]
        assert dropped.topic_id == 153
    finally:
        ls.close()


def test_tx_stop_unconfigures_the_client(link):
    handshake(link)
    link.server.stop()
    link.step(1040)
    assert not link.client.configured
    assert link.events("client", SyncLost)[0][1].reason == "TX_STOP from server"


def test_client_limits_512_in_1024_out(link):
    handshake(link)
    pwms = REG.msg("spinal/Pwms")
    # 1024-byte frame = 1016-byte payload = 4 + 2 * 506 values: fits; 507 values do not
    assert link.client.publish("motor_pwms", pwms.new(motor_value=[1] * 506)) == 1024
    assert link.client.publish("motor_pwms", pwms.new(motor_value=[1] * 507)) == -1
    link.step(1040)
    logs = [e for _, e in link.events("server", LogReceived)]
    assert logs == [LogReceived(3, "Message from device dropped: message larger than buffer.")]
    assert len(link.events("server", MessageReceived)) == 1
    # PC -> device: the device announced 512-byte buffers; larger payloads are refused
    cmd = REG.msg("spinal/FourAxisCommand")
    with pytest.raises(PayloadTooLarge, match="512"):
        link.server.publish("four_axes/command", cmd.new(base_thrust=[1.0] * 126))
    # raw oversize frame on the wire is rejected by the client parser, not delivered
    raw = encode_frame(108, cmd.encode(cmd.new(base_thrust=[1.0] * 126)))
    events = link.client.spin(raw, 1050)
    assert next(e.bad.reason for e in events if isinstance(e, FrameRejected)) == "oversize"
    assert not [e for e in events if isinstance(e, MessageReceived)]


def test_tx_ring_drops_frames_that_do_not_fit(link):
    handshake(link)
    link.client.take_output()
    imu = REG.msg("spinal/Imu")  # 60-byte payload: one 64-byte chunk... plus 8 -> two chunks
    sent = [link.client.publish("imu", imu.new()) for _ in range(70)]
    assert sent.count(-1) == 6 and link.client.counts["tx_ring_full"] == 6
    assert len(link.client.take_output()) == 64 * 68


def test_frame_timeout_20ms_at_the_client(link):
    handshake(link)
    cmd = REG.msg("spinal/FourAxisCommand")
    raw = encode_frame(108, cmd.encode(cmd.new(base_thrust=[1.0] * 4)))
    assert link.client.spin(raw[:9], 2000) == []
    late = link.client.spin(raw[9:], 2021)
    assert [e.bad.reason for e in late if isinstance(e, FrameRejected)] == ["timeout"]
    assert not [e for e in late if isinstance(e, MessageReceived)]
    assert link.client.spin(raw[:9], 3000) == []
    ok = link.client.spin(raw[9:], 3020)
    assert [e.topic for e in ok if isinstance(e, MessageReceived)] == ["four_axes/command"]


def test_bad_version_byte_while_unconfigured_requests_time():
    client = ClientSession.from_layout()
    client.spin(b"\xff\x00", 5)
    assert client.take_output() == bytes.fromhex("fffe0800f70a000000000000000000f5")
    client.spin(bytes.fromhex("fffe0000ff0000ff"), 10)
    client.take_output()
    client.spin(b"\xff\x00", 15)  # configured: no reaction
    assert client.take_output() == b""


def test_publish_before_handshake_is_not_sent():
    client = ClientSession.from_layout()
    assert client.publish("battery_voltage_status", REG.msg("std_msgs/Float32").new(data=16.2)) == 0
    assert client.log(C.LogLevel.INFO, "boot") > 0  # reserved ids always go out
    assert client.take_output()[5] == C.TopicId.LOG
