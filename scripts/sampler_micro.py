"""Micro costs of the plant-side fast paths against their plain forms (us per call)."""

import timeit

import numpy as np

from rdm.plant import Plant
from rdm.sim.json_record import encode_record, encode_record_plain

p = Plant("rdm", seed=0, ceiling_height=1.6, floor_height=0.0)
p.reset(base_position=(0, 0, 0.8))
p.step(5)
p.sync()
d = p._data
tr = p._tracker


def t(f, n=5000):
    return min(timeit.repeat(f, number=n, repeat=5)) / n * 1e6


gt = p._ground_truth()
rec = {k: getattr(gt, k) for k in gt.__dataclass_fields__}
st = {
    "t": 1.0,
    "state": "hover",
    "base_thrust": [np.float64(3.2)] * 4,
    "perch_status": None,
    "perch_thrust": [1.0] * 4,
    "duties": [0.6] * 4,
    "failsafes": 0,
}
duties = np.array([0.61, 0.62, 0.63, 0.64])
rows = [
    ("ground truth (no contact)", lambda: p._ground_truth(), lambda: p._ground_truth_plain()),
    ("contact measure (no contact)", lambda: tr.measure(d), lambda: tr.measure_plain(d)),
    ("truth record JSON", lambda: encode_record(rec), lambda: encode_record_plain(rec)),
    ("status record JSON", lambda: encode_record(st), None),
    ("IMU sample", lambda: p.imu(), lambda: p.imu_plain()),
    ("foot wrench sample", lambda: p.wrench("foot_wrench"), lambda: p.wrench_plain("foot_wrench")),
    ("rotor duties", lambda: p.set_rotor_duties(duties), lambda: p.set_rotor_duties_plain(duties)),
]
for name, fast, plain in rows:
    print(
        f"{name:30s} fast {t(fast):6.1f}  plain {t(plain):6.1f}"
        if plain
        else f"{name:30s} fast {t(fast):6.1f}"
    )
