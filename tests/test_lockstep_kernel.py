"""The lockstep loop's fast parts (rdm.nodes.lockstep_kernel): golden runs of the simulated
stack with the fast parts attached.

Oracle: golden runs (``tests/data/lockstep_kernel.json``): the SHA-256 of every log file a run
writes and of every node's Python-visible state (``_state``; the Spinal mirror's busy-ms state
is ``tests/test_spinal_kernel_busy.py``'s). The golden digests were recorded from runs whose
files and state equalled those of the stack without fast parts
(``StackOptions.lockstep_kernel=False``: every node's own tick); after a deliberate change of
the simulated bytes, ``RDM_WRITE_GOLDEN=1 python -m pytest tests/test_lockstep_kernel.py``
records them again (say why in the commit). The kernel's per-node counts show the fast paths
ran. Faults and the paths that leave the steady state are driven on purpose: a cut UART, a held
external wrench on the plant, a battery voltage that is a function of time, a truth sink that
changes a node, a paced run, a node that raises or whose tick is wrapped. The scenarios' own
runs (hover, flight, perching, ...) are the reference manifest's
(``tests/test_reference_manifest.py``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import golden_digests
import numpy as np
import pytest

from rdm.nodes.leptrino_sensor import LeptrinoSensorNode
from rdm.nodes.lockstep import Lockstep
from rdm.nodes.lockstep_kernel import attach_kernel, kind_of
from rdm.nodes.neuron_bank import NeuronBankNode
from rdm.nodes.plant_bridge import PlantBridge
from rdm.nodes.spinal_mirror import SpinalMirror
from rdm.scenarios.common import sim_stack_options
from rdm.scenarios.hover import HOVER_Z, make_script
from rdm.scenarios.stack import Stack, build_stack

Steps = Callable[[Stack], None]


def _spinal_state(spinal) -> tuple:
    """The Spinal mirror's busy-ms state the kernel writes back (docs/spinal.md)."""
    out = spinal.last_output
    uart = spinal.uart
    chain = uart._chain
    links = None
    if chain is not None:
        droppable, tapped, end = chain
        links = (
            None if droppable is None else (droppable.dropped, droppable.bytes_lost),
            None if tapped is None else (tapped.tx_bytes, tapped.rx_bytes),
            None if end.peer is None else bytes(end.peer.inbox),
        )
    return (
        spinal._next_control,
        spinal.counters.control_steps,
        None
        if out is None
        else (
            type(out),
            repr(out.duty),
            out.quaternion.tobytes(),
            out.angular_velocity.tobytes(),
            out.events,
        ),
        spinal.duties,
        spinal.duties is spinal._duties_to_master,
        spinal._duties_to_master,
        dict(spinal._last_pub),
        spinal._next_pub_ms,
        spinal._battery_due_ms,
        spinal.battery_voltage,
        dict(spinal.session.counts),
        spinal.session._tx_used,
        list(spinal.session.pending_frames),
        (uart.bytes_in, uart.bytes_out, uart.bytes_discarded, uart.write_errors, uart.read_errors),
        bytes(uart.pending),
        links,
    )


def _state(stack: Stack) -> dict:
    """Every Python-visible counter and clock the kernel's fast paths keep."""
    plant = stack.plant
    bank = stack.loop.nodes[1]
    sensor = stack.sensor
    bridge = stack.bridge
    d = plant._data
    return {
        "k": stack.loop.k,
        "ticks": dict(stack.loop.stats.ticks),
        "clock": stack.loop.clock.now,
        "spinal": stack.spinal.diagnostics(),
        "spinal_clock": (stack.spinal.now_ms, stack.spinal._now_s, stack.spinal._can_ms),
        "spinal_imu": (stack.spinal.gyro, stack.spinal.acc, stack.spinal.mag),
        "spinal_busy": _spinal_state(stack.spinal),
        "master": (stack.spinal.master.tx_count, stack.spinal.master._pending_events),
        "boards": [(b.tx_count, b.change_count, b.rx_count) for b in bank.boards],
        "bank_changes": bank._core.changes(),
        "bridge": (bridge.ticks, bridge.schedule.count, bridge.time_mismatches),
        "leptrino": (
            sensor.frames_sent,
            sensor.bytes_dropped,
            sensor.saturated_samples,
            dict(sensor.errors),
            sensor.wrench,
        ),
        "plant_flags": (plant._state.stale, plant._state.needs_step1, plant._state.version),
        "sleep": None
        if plant.sleep is None
        else (
            plant.sleep.pending,
            plant.sleep.allowed,
            plant.sleep.wakes,
            plant.sleep.sleep_on,
            plant.sleep.settled,
            plant.model.opt.enableflags,
            plant.sleep.last_ctrl.tobytes(),
            d.tree_asleep.tobytes(),
            plant.model.tree_sleep_policy.tobytes(),
        ),
        "rejected": plant.rejected_commands,
        "contact_gate": None
        if plant.contact_gate is None
        else (plant.contact_gate.off, plant.contact_gate.off_steps, plant.contact_gate.on_steps),
        "normals": (
            plant.imu_model._normals.taken,
            plant.wrench_models["foot_wrench"]._normals.taken,
        ),
        "qpos": d.qpos.tobytes(),
        "qvel": d.qvel.tobytes(),
        "ctrl": d.ctrl.tobytes(),
        "time": d.time,
        "tracker": (
            plant._tracker.last_contact_time,
            None if plant._tracker.anchor_pos is None else plant._tracker.anchor_pos.tobytes(),
        ),
    }


def _run(
    tmp: Path, kernel: bool, steps: Steps, script=None, **options
) -> tuple[dict, dict, dict | None]:
    """(files by relative path, state, kernel stats) of the stack driven by ``steps`` (the
    hover script unless ``script`` is given)."""
    options = {"speed": None, **options}
    opts = replace(sim_stack_options(0, "inproc", **options), lockstep_kernel=kernel)
    if script is None:
        script = make_script(np.array([0.483, 0.0, HOVER_Z]))
    stack = build_stack("k", tmp, opts, script)
    try:
        steps(stack)
        # The bridge's one state object: one schedule tick per loop tick of the bridge (the
        # loop's own count), each at the plant's time.
        bridge_ticks = stack.loop.stats.ticks["plant_bridge"]
        assert stack.bridge.ticks == bridge_ticks and stack.bridge.time_mismatches == 0
        state = _state(stack)
        stats = stack.loop.kernel.stats()
        if not kernel:  # the oracle: every tick in the node's own Python tick
            assert sum(stats["fast"]) == 0 and stats["physics_fast"] == 0
            stats = None
    finally:
        stack.close()
    root = Path(stack.folder.root)
    files = {str(p.relative_to(root)): p.read_bytes() for p in root.rglob("*") if p.is_file()}
    files = {k: v for k, v in files.items() if not k.startswith("plots")}
    return files, state, stats


GOLDEN = "lockstep_kernel.json"
#: State keys left to tests/test_spinal_kernel_busy.py (the Spinal mirror's private state).
_NOT_DIGESTED = ("spinal_busy",)


def _golden(
    tmp_path: Path,
    name: str,
    steps: Steps,
    make_script_=None,
    *,
    golden_file: str = GOLDEN,
    skip: tuple[str, ...] = _NOT_DIGESTED,
    **options,
) -> dict:
    """Run ``steps`` with the fast parts; every file and the state (but the keys in ``skip``)
    against the golden run ``name`` of ``tests/data/<golden_file>``; the kernel's stats.
    ``make_script_()`` gives the scenario script (default: hover); ``options`` go to the
    stack options."""
    script = make_script_() if make_script_ is not None else None
    files, state, stats = _run(tmp_path / "kernel", True, steps, script, **options)
    digests = {f"file:{key}": golden_digests.sha(data) for key, data in files.items()}
    digests.update(
        {
            f"state:{key}": golden_digests.sha(repr(value).encode())
            for key, value in state.items()
            if key not in skip
        }
    )
    golden_digests.check(golden_file, name, digests)
    assert stats is not None
    return stats


def _fast_counts(stack_nodes: list[str], stats: dict) -> dict[str, int]:
    return dict(zip(stack_nodes, stats["fast"], strict=True))


NODES = [
    "plant_bridge",
    "neurons",
    "spinal",
    "mocap",
    "onboard",
    "leptrino_foot",
    "script",
    "status",
]


def test_hover_with_a_cut_uart(tmp_path: Path) -> None:
    def steps(stack: Stack) -> None:
        stack.loop.run(2.6)
        stack.drop_uart(True)  # Spinal's fail-safe: the link is lost for 0.4 s
        stack.loop.run(0.4)
        stack.drop_uart(False)
        stack.loop.run(1.0)

    stats = _golden(tmp_path, "hover-cut-uart", steps)
    fast = _fast_counts(NODES, stats)
    # The kernel ran the steady ms itself: most bridge, bank, Leptrino and plant steps, and
    # a good share of Spinal's ms (its control and publishers stay Python's).
    assert fast["plant_bridge"] > 3000
    assert fast["neurons"] == 4000
    assert fast["spinal"] > 1000
    assert fast["leptrino_foot"] > 1500
    assert stats["physics_fast"] == 4000
    assert fast["onboard"] == fast["mocap"] == fast["script"] == 0
    # Spinal's routine busy ms ran in the kernel too (docs/spinal.md): control steps
    # (most of the 500 after the CAN boot), battery samples, imu and servo/states frames;
    # the step with an event (the arming ack) went on in Python.
    busy = stats["spinal_busy"]
    assert busy["steps"] > 450 and busy["battery_samples"] > 100
    assert busy["imu_frames"] > 400 and busy["servo_frames"] > 100
    assert busy["finish_step"] >= 1
    # The ms that read the onboard node's commands: received in Python, the rest of the ms
    # (CAN, publishers, output) here (docs/spinal.md "In the simulated stack").
    assert busy["receive_then_kernel"] > 100


def test_perching_contacts(tmp_path: Path) -> None:
    from rdm.scenarios import perching

    def steps(stack: Stack) -> None:
        stack.loop.run(16.0)  # flight, the approach, contact at 14.80 s, 1.2 s perched

    stats = _golden(
        tmp_path,
        "perching-16s",
        steps,
        lambda: perching.PerchingScript(perching.PERCHED_MOTION),
        onboard=perching.onboard_config(),
    )
    # Perched (1.17 s), the contact tracker only stamps the contact time: the kernel does
    # it; on the floor before take-off (other geoms touching, the anchor set) it is Python's.
    assert stats["tracker_fast"] > 1100
    busy = stats["spinal_busy"]  # Spinal's busy ms in the kernel through the whole flight
    assert busy["steps"] > 2500 and busy["imu_frames"] > 2000 and busy["servo_frames"] > 500


def test_held_external_wrench_takes_the_python_step(tmp_path: Path) -> None:
    def steps(stack: Stack) -> None:
        stack.loop.run(2.5)
        stack.plant.apply_body_wrench("end_effector", force=(1.5, 0.0, -0.5))
        stack.loop.run(0.5)
        stack.plant.apply_body_wrench("end_effector")  # zero: released
        stack.loop.run(0.3)

    stats = _golden(tmp_path, "hover-held-wrench", steps)
    assert stats["physics_python"] >= 500  # every step while the wrench is held
    assert stats["physics_fast"] > 2000


def test_battery_voltage_of_time_leaves_the_bridge_to_python(tmp_path: Path) -> None:
    def steps(stack: Stack) -> None:
        stack.loop.run(1.8)
        stack.bridge.set_battery(lambda t: 25.2 if t < 2.2 else 24.6)
        stack.loop.run(0.8)

    stats = _golden(tmp_path, "hover-battery-of-time", steps)
    assert stats["python"][0] >= 800  # the bridge: Python for every tick with the function


def test_a_truth_sink_that_changes_a_node_has_its_plans_re_read(tmp_path: Path) -> None:
    def steps(stack: Stack) -> None:
        stack.loop.run(1.0)
        inner = stack.bridge._truth_sink

        def sink(gt) -> None:
            inner(gt)
            stack.sensor.temperature += 1  # in every later Leptrino frame

        stack.bridge._truth_sink = sink
        stack.bridge.truth_sink_touches = None  # unknown sink: every plan re-read
        stack.loop.run(0.6)

    stats = _golden(tmp_path, "hover-truth-sink-changes-leptrino", steps, log=True)
    assert stats["fast"][5] > 250  # Leptrino frames kept coming from the kernel


def test_a_paced_run(tmp_path: Path) -> None:
    """Paced to 4x real time, the loop sleeps after most ticks (Python may run in other
    threads then: every part is written back first); the bytes and state are the golden
    run's, and the fast parts still ran."""

    def steps(stack: Stack) -> None:
        stack.loop.run(0.6)

    stats = _golden(tmp_path, "hover-paced", steps, speed=4.0, log=False)
    fast = _fast_counts(NODES, stats)
    assert fast["neurons"] == 600 and stats["physics_fast"] > 500


def _stopping_script(at: float) -> Callable[[Stack, float], None]:
    inner = make_script(np.array([0.483, 0.0, HOVER_Z]))

    def script(stack: Stack, now: float) -> None:
        inner(stack, now)
        if math.isclose(now, at):
            stack.loop.stop()

    return script


@pytest.mark.parametrize("kernel", [True, False])
def test_a_node_stops_the_loop_after_its_tick(tmp_path: Path, kernel: bool) -> None:
    opts = replace(sim_stack_options(0, "inproc", speed=None, log=False), lockstep_kernel=kernel)
    stack = build_stack("stop", tmp_path, opts, _stopping_script(1.23))
    try:
        stack.loop.run(3.0)
        assert stack.loop.k == 1231  # the ms of the stop ran to its end (physics included)
        assert stack.loop.stats.ticks["script"] == 124
        assert stack.loop.clock.now == pytest.approx(1.23)
    finally:
        stack.close()


class _Boom(RuntimeError):
    pass


def test_a_raising_node_leaves_its_state_written_back(tmp_path: Path) -> None:
    def steps(stack: Stack) -> None:
        stack.loop.run(1.5)
        inner = stack.mocap.tick

        def tick(now: float) -> None:
            if now > 1.7:
                raise _Boom(now)
            inner(now)

        stack.mocap.tick = tick  # read afresh by both loops at the next run
        with pytest.raises(_Boom):
            stack.loop.run(1.0)

    _golden(tmp_path, "hover-raising-node", steps, log=False)


def test_a_wrapped_tick_runs_instead_of_the_fast_path(tmp_path: Path) -> None:
    calls: list[float] = []

    def steps(stack: Stack) -> None:
        stack.loop.run(1.0)
        inner = stack.spinal.tick

        def counting(now: float) -> None:
            calls.append(now)
            inner(now)

        stack.spinal.tick = counting
        stack.loop.run(0.5)
        del stack.spinal.tick  # the class's own tick again: fast path allowed
        stack.loop.run(0.5)

    stats = _golden(tmp_path, "hover-wrapped-tick", steps, log=False)
    # The wrapper ran at every Spinal tick of the middle half second.
    assert len(calls) == 500
    assert stats["fast"][2] > 0  # ... and the kernel's Spinal fast path ran outside it


class _Recorder:
    """A toy node that records what it sees (tick order, the clock at its tick)."""

    def __init__(self, name: str, period: float, log: list, clock_of) -> None:
        self.name = name
        self.period = period
        self._log = log
        self._clock = clock_of

    def tick(self, now: float) -> None:
        self._log.append((self.name, now, self._clock().now))


class _Physics:
    def __init__(self, log: list) -> None:
        self._log = log

    def step(self, n: int = 1) -> None:
        self._log.append(("physics", n))


def test_python_only_nodes_tick_in_order_with_the_clock_set() -> None:
    """A loop of Python nodes only (no fast part, nothing to attach): the kernel ticks each
    at ``k % every == offset`` in list order with the clock at ``k * dt``, then the physics.
    Oracle: the log written out here from the periods and offsets. Catches a clock left at
    the previous tick (it is set lazily, before Python code), an offset ignored, a node
    order swapped or a physics step before the nodes."""
    log: list = []
    holder: list = []
    nodes = [
        _Recorder("a", 0.001, log, lambda: holder[0].clock),
        _Recorder("b", 0.005, log, lambda: holder[0].clock),
        _Recorder("c", 0.025, log, lambda: holder[0].clock),
    ]
    loop = Lockstep(nodes, physics=_Physics(log), offsets={"b": 2, "c": 7})
    holder.append(loop)
    attach_kernel(loop)
    loop.run_ticks(137)
    loop.run(0.2)
    want: list = []
    for k in range(337):
        t = k * 0.001
        for name, every, offset in (("a", 1, 0), ("b", 5, 2), ("c", 25, 7)):
            if k % every == offset:
                want.append((name, t, t))
        want.append(("physics", 1))
    assert log == want
    assert loop.k == 337
    assert loop.stats.ticks == {"a": 337, "b": 67, "c": 14}
    assert loop.clock.now == 336 * 0.001
    stats = loop.kernel.stats()
    assert sum(stats["fast"]) == 0 and stats["physics_python"] == 337


def test_kind_of_reads_the_class_own_part_only() -> None:
    """The four node classes with a kernel part, by the part names the kernel's plans use;
    a subclass (which may override ``tick``) has none. Catches ``getattr`` (inherited part)
    in ``kind_of`` or a part name swapped between two classes."""
    expected = {
        PlantBridge: "bridge",
        NeuronBankNode: "bank",
        SpinalMirror: "spinal",
        LeptrinoSensorNode: "leptrino",
    }
    for cls, part in expected.items():
        assert kind_of(object.__new__(cls)) == part
        assert kind_of(object.__new__(type("Sub", (cls,), {}))) is None
    assert kind_of(object()) is None
