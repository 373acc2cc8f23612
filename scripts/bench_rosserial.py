"""Throughput of the rosserial mirror (a measurement, not a test; docs/rosserial.md).

usage: python scripts/bench_rosserial.py
"""

import json
import time
from pathlib import Path

from rdm.protocol.rosserial import ClientSession, ServerSession
from rdm.protocol.rosserial.framing import FrameParser
from rdm.protocol.rosserial.registry import spinal_registry

G = json.loads(
    (
        Path(__file__).resolve().parents[1] / "firmware_protocol/spinal/golden_frames.json"
    ).read_text()
)
stream = b"".join(bytes.fromhex(v["hex"]) for v in G["topics"]) * 200
t = time.perf_counter()
p = FrameParser(1022)
ev = p.feed(stream)
dt = time.perf_counter() - t
print(f"parser, one feed: {len(stream) / dt / 1e6:.1f} MB/s ({len(ev) / dt / 1e3:.0f} kframes/s)")
t = time.perf_counter()
p = FrameParser(1022)
n = 0
for i in range(0, len(stream), 64):
    n += len(p.feed(stream[i : i + 64]))
dt = time.perf_counter() - t
print(f"parser, 64-byte chunks: {len(stream) / dt / 1e6:.1f} MB/s")
r = spinal_registry()
imu = r.msg("spinal/Imu")
m = imu.new(quaternion=[0, 0, 0, 1.0])
N = 20000
t = time.perf_counter()
for _ in range(N):
    b = imu.encode(m)
e = time.perf_counter() - t
t = time.perf_counter()
for _ in range(N):
    imu.decode(b)
d = time.perf_counter() - t
print(f"spinal/Imu encode {e / N * 1e6:.1f} us, decode {d / N * 1e6:.1f} us")
c = ClientSession.from_layout()
s = ServerSession()
s.start(0.0)
c.spin(s.take_output(), 1)
s.feed(c.take_output(), 0.001)
N = 5000
t = time.perf_counter()
for k in range(N):
    c.publish("imu", m)
    s.feed(c.take_output(), 0.002 + k * 1e-4)
dt = time.perf_counter() - t
print(f"client publish imu -> server MessageReceived: {dt / N * 1e6:.1f} us per message")
