"""The lockstep bench's in-flight note: the real-time factor of the ticks after take-off,
checked on synthetic per-tick times whose factor is known by construction."""

from __future__ import annotations

import numpy as np

from rdm.bench import lockstep


def test_airborne_note_uses_only_the_ticks_after_take_off():
    first = round(lockstep.AIRBORNE_FROM_S * 1000)  # 1 ms ticks
    # 1 ms of wall per tick on the floor (1x), 50 us per tick in the air (20x)
    ns = np.array([1_000_000] * first + [50_000] * 1500, dtype=np.int64)
    (note,) = lockstep._airborne_note(ns)
    assert "20.00x real time" in note and "1.5 simulated s" in note


def test_airborne_note_is_empty_for_a_run_that_ends_on_the_floor():
    ns = np.full(round(lockstep.AIRBORNE_FROM_S * 1000), 1_000_000, dtype=np.int64)
    assert lockstep._airborne_note(ns) == []


def test_kernel_note_names_the_nodes_run_in_rust_with_their_counts():
    stats = {
        "nodes": ["plant_bridge", "onboard"],
        "fast": [900, 0],
        "python": [100, 40],
        "physics_fast": 1000,
        "physics_python": 0,
    }
    (note,) = lockstep._kernel_note(stats)
    assert note == "lockstep kernel, ticks run in Rust: plant_bridge 900/1000, physics 1000/1000"


def test_the_median_run_is_reported_and_every_run_noted():
    def run(wall: float) -> lockstep.Run:
        return (np.zeros(1, dtype=np.int64), wall, wall, None)

    runs = [run(w) for w in (0.30, 0.20, 0.25, 0.40, 0.22)]
    assert lockstep.median_run(runs)[1] == 0.25
    assert lockstep.median_run(runs[:4])[1] == 0.25  # even count: the lower middle
    (note,) = lockstep._runs_note(runs, 4.0)
    assert note.endswith("13.3x, 20.0x, 16.0x, 10.0x, 18.2x")
    assert lockstep._runs_note(runs[:1], 4.0) == []


def test_reference_loop_gives_a_time_and_is_noted():
    # a time, not a speed target (those live in rdm bench): positive and finite
    ms = lockstep.reference_ms(20_000)
    assert 0.0 < ms < float("inf")
    (note,) = lockstep._reference_note([101.4, 140.6])
    assert "ms): 101, 141 (the interpreter-bound speed" in note
    assert lockstep._reference_note([]) == []
