"""The full simulated robot: plant + every firmware/PC node, each message on its real wire.

::

    MuJoCo plant --PlantBridge (1 kHz)--> Neuron bank (4 boards) --CAN wire--> SpinalMirror (200 Hz)
         ^   IMU -> SpinalMirror.set_imu_sample              rosserial on a UART (inproc or pty)
         |   foot F/T -> LeptrinoSensorNode --Leptrino UART--> OnboardNode (40 Hz)
         |   ground-truth CoG (mocap, 100 Hz) ------------------------^
         +-- ESC duties / servo goals <-- Neuron mirrors <-- CAN <-- SpinalMirror

Nothing short-cuts a wire: the onboard node only sees rosserial bytes from Spinal, Leptrino
frames from the foot sensor and the mocap pose; Spinal only sees rosserial bytes, the IMU and
the CAN frames of the Neurons; the plant only sees what the Neurons' ESCs and servos output.
"""

from __future__ import annotations

import contextlib
import itertools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from rdm.link.can import open_can
from rdm.link.can_wire import CanWireLink, WireCandump
from rdm.link.uart_pipe import open_inproc_uart
from rdm.nodes.leptrino_sensor import LeptrinoSensorNode
from rdm.nodes.lockstep import Lockstep
from rdm.nodes.lockstep_kernel import attach_kernel
from rdm.nodes.neuron_bank import NeuronBankNode, NeuronSpec
from rdm.nodes.neuron_mirror import NeuronMirror
from rdm.nodes.onboard import OnboardNode
from rdm.nodes.onboard_arming import FlightState
from rdm.nodes.onboard_config import OnboardConfig
from rdm.nodes.onboard_signals import onboard_signals
from rdm.nodes.plant_bridge import BusLayout, PlantBridge, default_layout
from rdm.nodes.servo_model import ServoConfig
from rdm.nodes.spinal_mirror import SpinalMirror
from rdm.plant import EscParams, Plant, ServoParams
from rdm.plant.sensors import imu_model_of_seed
from rdm.sim import CandumpCapture, McapLogger, RunFolder, open_tapped_pty
from rdm.sim.live import LiveTee, live_publisher
from rdm.sim.pty_pair import open_device_pty

from .external_onboard import ExternalOnboard
from .mocap_node import MocapNode, MocapSensor

_FLOAT64 = np.dtype(np.float64)


def _free_channel() -> str:
    """``rdm-sim``, or ``rdm-sim-N`` when another stack in this process still holds it: the
    name is in the candump, so same-seed runs (one after the other) give identical logs."""
    from rdm.link import inproc_can

    for n in itertools.count():
        name = "rdm-sim" if n == 0 else f"rdm-sim-{n}"
        if name not in inproc_can._channels:
            return name
    raise AssertionError("unreachable")


class DroppableLink:
    """A byte-link end that can be cut: while ``dropped`` nothing is read or written (the
    bytes are lost, as on an unplugged cable). Used to test Spinal's fail-safe."""

    def __init__(self, link: Any) -> None:
        self.link = link
        self.dropped = False
        self.bytes_lost = 0

    def read_available(self) -> bytes:
        data = self.link.read_available()
        if self.dropped:
            self.bytes_lost += len(data)
            return b""
        return data

    def write(self, data: bytes) -> int:
        if self.dropped:
            self.bytes_lost += len(data)
            return len(data)
        return self.link.write(data)

    def close(self) -> None:
        self.link.close()


def quaternion_yaw(q_wxyz: np.ndarray) -> float:
    """ZYX yaw of a (w, x, y, z) quaternion."""
    w, x, y, z = (float(v) for v in q_wxyz)
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


class ScriptNode:
    """Runs a scenario's script ``f(now)`` (targets, perch requests, pushes) at its period.
    ``kernel_touches``: the lockstep kernel's parts the script reads or changes
    (``rdm.nodes.lockstep_kernel``); None (default): any."""

    def __init__(
        self,
        fn: Callable[[float], None],
        period: float = 0.01,
        name: str = "script",
        kernel_touches: tuple[str, ...] | None = None,
    ) -> None:
        self.fn = fn
        self.period = period
        self.name = name
        self.kernel_touches = kernel_touches

    def tick(self, now: float) -> None:
        self.fn(now)


@dataclass
class StackOptions:
    """Everything the stack builder takes (defaults: the documented simulated robot)."""

    seed: int = 0
    #: The robot: a shipped name or the path of a robot TOML. Its rotor count sets the
    #: onboard node's ``motor_num`` and Spinal's ESC outputs; its description the plant's.
    robot: str = "rdm"
    uart: str = "inproc"  # or "pty"
    ceiling_height: float | None = 1.6
    floor_height: float | None = 0.0
    base_position: tuple[float, float, float] = (0.0, 0.0, 0.12)
    q0: tuple[float, ...] | None = None
    boot_delay_ms: int = 100
    spinal_rate_hz: float = 200.0
    gyro_calib_duration_s: float = 0.5
    #: Spinal's IMU prefilters and complementary factors rescaled so that ``spinal_rate_hz``
    #: keeps the firmware's 1 kHz time constants (True), or the firmware's per-sample factors
    #: (False: at 200 Hz the gyro low-pass lag becomes 60 ms instead of 12 ms and the roll
    #: loop of the simulated robot goes unstable). ASSUMPTION (docs/sim.md).
    spinal_time_matched: bool = True
    onboard: OnboardConfig | None = None
    leptrino_rate_hz: float = 500.0
    mocap_period: float = 0.01
    #: What motion capture gives the onboard node (:class:`MocapSensor`): the true CoG state
    #: (default), or ``MocapSensor()``: the marker body's pose with noise and latency, as a
    #: real system gives it (docs/flying.md "Motion capture").
    mocap: MocapSensor = field(default_factory=lambda: MocapSensor(source="truth"))
    truth_period: float = 0.01
    log: bool = True
    speed: float | None = None
    #: The Neuron CAN frames go from Spinal's CAN master to the Neuron bank on a
    #: :class:`rdm.link.can_wire.CanWireLink` (no python-can bus; the candump is the same
    #: bytes, docs/canbus.md). The channel then admits no other python-can endpoint
    #: (CanWireError); False puts them on an in-process python-can channel.
    can_wire: bool = True
    #: Rotor (ESC + motor) first-order lag [s]; None = the plant's default (0.05 s).
    #: ASSUMPTION 0.01 s: with 0.05 s the LQI roll loop (I_xx = 0.004 kg m^2) is unstable.
    esc_tau: float | None = 0.01
    #: Battery voltage [V] (a full 6S pack, the Hydrus PwmInfo reference: 20 N at max duty).
    battery_voltage: float = 25.2
    #: Adds world objects to the MuJoCo spec before it compiles (``Plant(scene=...)``).
    scene: Callable[[Any], None] | None = None
    #: Called as ``progress(stack, now)`` once per simulated second (``rdm sim``'s display).
    progress: Callable[[Any, float], None] | None = None
    #: Spinal's flash holds an accelerometer calibration (JSK: ``imu_calib`` CALIB_ACC on a
    #: level surface, then SAVE_CALIB_DATA; the estimator subtracts the stored bias,
    #: jsk-wire-protocols.md sec. 3.2): the simulated IMU's constant bias, i.e. the average of
    #: a long calibration on the level floor, where the simulated robot rests (tilt < 1e-5
    #: deg). ASSUMPTION: a perfect calibration. False: an empty flash (bias 0, the behaviour
    #: before); then seed 1's accelerometer bias (-0.13 m/s^2 in y: 0.8 deg of roll) tips the
    #: perched plate onto its edges (ZMP on the edge 10.5 % of the time, docs/sim.md).
    imu_acc_calibrated: bool = True
    #: Give the lockstep loop its fast parts (:mod:`rdm.nodes.lockstep_kernel`): the same
    #: ticks, the same bytes in every log (tests/test_lockstep_kernel.py), the steady
    #: milliseconds of the firmware side without Python. False: every tick is the node's
    #: own Python ``tick``.
    lockstep_kernel: bool = True
    #: Joint servo model. ASSUMPTION: a stiff position servo (kp 150 N m/rad, kv 5 N m s/rad,
    #: about 1 deg of error at 2.6 N m, torque limited to the stall torque) as a Dynamixel X
    #: holds its goal; the plant's softer default (kp 30) lets q2 sag 0.35 rad at take-off.
    servo: ServoParams | None = field(default_factory=lambda: ServoParams(kp=150.0, kv=5.0))
    #: The resting robot sleeps in MuJoCo until a command, a push or a contact wakes it
    #: (``Plant(sleep=...)``, :mod:`rdm.plant.sleep`): on the floor during the boot the
    #: physics then costs almost nothing. False: always awake (the trajectory differs by the
    #: ~1e-5 the sleeping robot does not creep).
    plant_sleep: bool = True
    #: Skip MuJoCo's collision detection in steps that provably have no contact
    #: (``Plant(contact_gate=...)``, :mod:`rdm.plant.contact_gate`): the same bytes either
    #: way, ~3 us less per simulated ms in flight. False: collide in every step.
    plant_contact_gate: bool = True
    #: MuJoCo's sensors only in the forward pass a reading runs, not in every step
    #: (``Plant(lazy_sensors=...)``, docs/plant.md "Lazy sensors"): the same bytes either
    #: way, ~5k instructions less per simulated ms. False: sensors in every step.
    plant_lazy_sensors: bool = True
    #: Record the in-process onboard node into this folder (:mod:`rdm.nodes.flight_recorder`:
    #: its port bytes and inputs, for ``rdm replay``); a relative path is inside the run
    #: folder (``rdm sim --record-onboard``: ``onboard``); None: not recorded.
    record_onboard: str | None = None


#: Feed-forward lead of the joint servo goals on a planned path that the scenarios configure
#: (``OnboardConfig.servo_lead_s``) for the simulated servos above. Identified, not tuned to a
#: metric: with no lead the joints trail the plan by 50-52 ms in both stages of ``tracking``
#: (``rdm.scenarios.servo_lag.joint_lags``): the servo's kv/kp = 33 ms, the 40 Hz goal hold
#: (12.5 ms on average) and the Spinal -> Neuron -> servo hand-over (docs/scenarios.md,
#: "Servo goals ahead of the plan").
SIM_SERVO_LEAD_S = 0.05


@dataclass
class Stack:
    """The built stack; ``loop.run(seconds)`` advances it. Close with :meth:`close`."""

    plant: Plant
    layout: BusLayout
    #: The board views of the Neuron bank.
    neurons: list
    spinal: SpinalMirror
    onboard: OnboardNode
    sensor: LeptrinoSensorNode
    bridge: PlantBridge
    mocap: MocapNode
    loop: Lockstep
    folder: RunFolder
    #: the signal log: a McapLogger, a LiveTee (rdm sim --live) or None
    logger: Any
    candump: CandumpCapture | None
    spinal_link: DroppableLink
    onboard_link: DroppableLink
    truth: list = field(default_factory=list)
    status: list = field(default_factory=list)
    closers: list = field(default_factory=list)

    def close(self) -> None:
        for c in self.closers:
            with contextlib.suppress(Exception):
                c()
        self.closers = []

    def drop_uart(self, dropped: bool = True) -> None:
        """Cut (or restore) the Spinal <-> onboard UART in both directions."""
        self.spinal_link.dropped = dropped
        self.onboard_link.dropped = dropped


def spinal_flash_calibration(opt: StackOptions | Any) -> dict[str, list[float]]:
    """Spinal estimator overrides for the calibration its flash holds under ``opt``
    (``imu_acc_calibrated``: ``acc_bias`` = the bias of the IMU that ``make_plant(opt)``
    draws); empty for an uncalibrated flash. ``opt`` may be any object with the fields."""
    if not opt.imu_acc_calibrated:
        return {}
    return {"acc_bias": imu_model_of_seed(opt.seed).accel_bias.tolist()}


def make_plant(opt: StackOptions) -> tuple[Plant, np.ndarray]:
    """The MuJoCo plant of the options, reset to ``q0`` at ``base_position``; returns it and q0
    (shared by the lockstep stack and the ``rdm hil`` robot process)."""
    plant = Plant(
        opt.robot,
        seed=opt.seed,
        ceiling_height=opt.ceiling_height,
        floor_height=opt.floor_height,
        servo=opt.servo,
        esc=None if opt.esc_tau is None else EscParams(tau=opt.esc_tau),
        scene=opt.scene,
        sleep=opt.plant_sleep,
        contact_gate=opt.plant_contact_gate,
        lazy_sensors=opt.plant_lazy_sensors,
    )
    q0 = np.zeros(len(plant.joint_names)) if opt.q0 is None else np.asarray(opt.q0, float)
    plant.reset(q0=q0, base_position=opt.base_position)
    return plant, q0


def _board_configs(
    plant: Plant, q0: np.ndarray
) -> tuple[BusLayout, list[tuple[int, list[ServoConfig]]]]:
    """The default bus layout and each board's (slave id, servo configs) with servos at q0."""
    layout = default_layout(plant.description)
    q0_map = dict(zip(plant.joint_names, q0.tolist(), strict=True))
    return layout, [(nl.slave, layout.servo_configs(nl.slave, q0_map)) for nl in layout.neurons]


def make_neurons(
    plant: Plant, q0: np.ndarray, open_bus: Callable[[int], Any]
) -> tuple[BusLayout, list[NeuronMirror]]:
    """The robot's Neuron mirrors on its default bus layout, servos starting at ``q0``;
    ``open_bus(slave)`` gives each board its CAN bus."""
    layout, boards = _board_configs(plant, q0)
    neurons = [
        NeuronMirror(open_bus(slave), slave, configs, plant_driven=True)
        for slave, configs in boards
    ]
    return layout, neurons


def make_neuron_bank(plant: Plant, q0: np.ndarray, bus: Any) -> tuple[BusLayout, NeuronBankNode]:
    """The same boards as :func:`make_neurons` as one Rust-backed node on ``bus`` (board
    views in ``bank.boards``, layout order)."""
    layout, boards = _board_configs(plant, q0)
    specs = [NeuronSpec(slave, tuple(configs), plant_driven=True) for slave, configs in boards]
    return layout, NeuronBankNode(bus, specs)


def make_bridge(
    plant: Plant,
    neurons: Sequence[Any],
    layout: BusLayout,
    opt: StackOptions,
    *,
    imu_sink: Callable[..., None],
    battery_sink: Callable[[float], None],
    foot_sensor: Any,
    truth_sink: Callable[[Any], None],
    truth_sink_touches: Sequence[str] | None = None,
) -> PlantBridge:
    """The plant bridge at the options' rates: IMU to ``imu_sink`` (Spinal), battery voltage
    to ``battery_sink``, the foot wrench to the Leptrino mirror ``foot_sensor``, ground truth
    to ``truth_sink`` (which changes ``truth_sink_touches``, see :class:`PlantBridge`; shared
    by the lockstep stack and the ``rdm hil`` robot process)."""
    return PlantBridge(
        plant,
        neurons,
        layout,
        imu_sink=imu_sink,
        battery_voltage=opt.battery_voltage,
        battery_sinks=[battery_sink],
        wrench_sinks={"foot_wrench": foot_sensor.set_wrench_values},
        wrench_period=1.0 / opt.leptrino_rate_hz,
        truth_sink=truth_sink,
        truth_period=opt.truth_period,
        truth_sink_touches=truth_sink_touches,
    )


def build_stack(
    name: str,
    base: str | Path,
    options: StackOptions,
    script: Callable[[Stack, float], None] | None = None,
    script_period: float = 0.01,
) -> Stack:
    """Wire the full stack into a run folder ``<base>/<name>-seed<seed>`` (made empty,
    :class:`RunFolder`). A build that fails, Ctrl-C included, closes what it had opened (no
    bus or port left behind) before the error goes on."""
    folder = RunFolder.create(name, base=base, seed=options.seed)
    opened: list[Callable[[], Any]] = []
    try:
        return _wire(folder, options, script, script_period, opened)
    except BaseException:
        for close in reversed(opened):
            with contextlib.suppress(Exception):
                close()
        raise


def _wire(
    folder: RunFolder,
    opt: StackOptions,
    script: Callable[[Stack, float], None] | None,
    script_period: float,
    opened: list[Callable[[], Any]],
) -> Stack:
    """:func:`build_stack` into ``folder``; appends to ``opened`` the close of each part it
    opens, as it opens it."""
    plant, q0 = make_plant(opt)
    channel = _free_channel()
    wire = CanWireLink(channel, logging=opt.log) if opt.can_wire else None
    if wire is not None:
        opened.append(wire.shutdown)
    layout, bank = make_neuron_bank(plant, q0, wire or open_can(f"inproc:{channel}"))
    neurons: list = list(bank.boards)
    neuron_nodes: list = [bank]
    opened.append(bank.close)
    barriers: list = []
    # The captures' time index (rdm.link.capture_index): the plant's time is the loop's while
    # the nodes tick, and the lockstep kernel writes through the same file objects.
    clock = lambda: plant.time  # noqa: E731
    if opt.uart == "pty":
        s_dev, s_host, b1 = open_tapped_pty(folder.uart_dir, "spinal", ".bin", clock)
        f_dev, f_host, b2 = open_tapped_pty(folder.uart_dir, "leptrino_foot", ".lep", clock)
        barriers = [b1, b2]
    elif opt.uart == "inproc":
        s_dev, s_host = open_inproc_uart(folder.uart_dir, "spinal", ".bin", clock)
        f_dev, f_host = open_inproc_uart(folder.uart_dir, "leptrino_foot", ".lep", clock)
    elif opt.uart == "external":  # the onboard node is another process (rdm onboard)
        s_dev, s_host = open_device_pty(folder.uart_dir, "spinal", ".bin", clock)
        f_dev, f_host = open_device_pty(folder.uart_dir, "leptrino_foot", ".lep", clock)
    else:
        raise ValueError(f"uart={opt.uart!r}: 'inproc', 'pty' or 'external'")
    opened.extend((s_dev.close, s_host.close, f_dev.close, f_host.close))
    spinal_link, onboard_link = DroppableLink(s_dev), DroppableLink(s_host)
    spinal = SpinalMirror(
        spinal_link,
        wire or open_can(f"inproc:{channel}"),
        rate_hz=opt.spinal_rate_hz,
        boot_delay_ms=opt.boot_delay_ms,
        gyro_calib_duration_s=opt.gyro_calib_duration_s,
        time_matched=opt.spinal_time_matched,
        motor_outputs=len(plant.description.rotors),
        **spinal_flash_calibration(opt),
    )
    opened.append(spinal.close)
    config = opt.onboard or OnboardConfig()
    from dataclasses import replace

    if config.initial_q is None:
        config = replace(config, initial_q=tuple(q0.tolist()))
    if config.motor_num != len(plant.description.rotors):
        config = replace(config, motor_num=len(plant.description.rotors))
    external = opt.uart == "external"
    onboard: Any = (
        ExternalOnboard(config, s_host.port.port, f_host.port.port)
        if external
        else OnboardNode(onboard_link, f_host, robot=_onboard_robot(opt.robot), config=config)
    )
    opened.append(onboard.close)
    recorder = None
    if opt.record_onboard is not None and not external:
        from rdm.nodes.flight_recorder import record_node

        recorder = record_node(onboard, folder.root / opt.record_onboard, "rdm")
        opened.append(recorder.close)
    sensor = LeptrinoSensorNode(f_dev, "CFS034CA301U", rate_hz=opt.leptrino_rate_hz)
    logger: Any = McapLogger(folder.mcap) if opt.log else None
    if logger is not None:
        opened.append(logger.finish)
    live = live_publisher()
    if live is not None:  # rdm sim --live: the same records to the Foxglove server
        logger = LiveTee(logger, live)
    candump: Any = None
    if opt.log:
        candump = (
            WireCandump(folder.candump, wire)
            if wire is not None
            else CandumpCapture(folder.candump, channel=channel)
        )
        opened.append(candump.close)
    truth: list = []

    def truth_sink(gt: Any) -> None:
        truth.append(gt)
        if logger is not None:
            logger.log_truth(gt)

    bridge = make_bridge(
        plant,
        neurons,
        layout,
        opt,
        imu_sink=spinal.set_imu_sample,
        battery_sink=spinal.set_battery_voltage,
        foot_sensor=sensor,
        truth_sink=truth_sink,
        truth_sink_touches=(),  # it only keeps and logs the record
    )
    mocap = MocapNode(plant, onboard, opt.mocap_period, opt.mocap, seed=opt.seed)
    status_log: list = []
    nodes: list = [bridge, *neuron_nodes, spinal, mocap, *([] if external else [onboard]), sensor]
    stack = Stack(
        plant,
        layout,
        neurons,
        spinal,
        onboard,
        sensor,
        bridge,
        mocap,
        None,  # type: ignore[arg-type]  # loop set below
        folder,
        logger,
        candump,
        spinal_link,
        onboard_link,
        truth,
        status_log,
    )
    if script is not None:
        touches = getattr(script, "kernel_touches", None)  # what the scenario declares
        nodes.append(ScriptNode(lambda t: script(stack, t), script_period, kernel_touches=touches))
    if not external:  # it reads the in-process node
        nodes.append(StatusNode(stack))
    if opt.progress is not None:
        report = opt.progress
        nodes.append(ScriptNode(lambda t: report(stack, t), 1.0, name="progress"))
    stack.loop = Lockstep(
        nodes, physics=plant, can_channels=[channel], barriers=barriers, speed=opt.speed
    )
    if opt.lockstep_kernel and not barriers and not external:
        attach_kernel(stack.loop, plant)
    stack.closers = [
        onboard.close,
        *([logger.finish] if logger else []),
        *([candump.close] if candump else []),
        spinal.close,
        onboard_link.close,
        f_dev.close,
        f_host.close,
        *[n.close for n in neuron_nodes],
        *([recorder.close] if recorder is not None else []),
    ]
    return stack


def _onboard_robot(robot: str) -> Any:
    """The onboard node's model of ``robot`` (None: its default, the shipped RDM)."""
    if robot == "rdm":
        return None
    from rdm.model import Robot

    return Robot.load(robot)


class StatusNode:
    """40 Hz record of what the PC and Spinal report (perching QP status, thrusts, state), to
    the MCAP (``/onboard/status``) and to ``stack.status``; with a logger also the signals
    the PC's controller works with (``/onboard/signals``: :meth:`signals`)."""

    name = "status"
    period = 0.025
    #: It reads the onboard node and the Spinal mirror (its duty list, which the lockstep
    #: kernel's Spinal busy ms defer: docs/spinal.md), and changes neither.
    kernel_touches = ("spinal",)

    def __init__(self, stack: Stack) -> None:
        self.stack = stack

    def tick(self, now: float) -> None:
        s = self.stack
        rec = self.record(now)
        s.status.append(rec)
        if s.logger is not None:
            s.logger.log_json("/onboard/status", now, rec)
            s.logger.log_json("/onboard/signals", now, self.signals(now))

    def signals(self, now: float) -> dict[str, Any]:
        """What the onboard PC's controller saw and commanded at its last tick
        (:func:`rdm.nodes.onboard_signals.onboard_signals`)."""
        return onboard_signals(self.stack.onboard, now)

    def record(self, now: float) -> dict[str, Any]:
        """The status record at ``now``: the onboard state's value, the last command's base
        thrust, perching QP status and perching thrusts, Spinal's duties and failsafe count
        (each property read once)."""
        s = self.stack
        onboard = s.onboard
        c = onboard.last_command
        perch = getattr(c, "perch", None) if c is not None else None
        st = onboard.state
        if type(st) is FlightState:  # a plain Enum: ``value`` is ``_value_``
            state = st._value_
        else:
            state = st.value if hasattr(st, "value") else str(st)
        perch_thrust = _floats_of(getattr(c, "perch_thrust", None))
        failsafes = s.spinal.counters.failsafes
        return {
            "t": now,
            "state": state,
            "base_thrust": list(c.base_thrust) if c is not None else None,
            "perch_status": _perch_status(perch),
            "perch_thrust": perch_thrust,
            "duties": list(s.spinal.duties),
            "failsafes": sum(failsafes.values()) if hasattr(failsafes, "values") else 0,
        }


def _perch_status(perch: Any) -> str | None:
    if perch is None:
        return None
    st = getattr(perch, "status", None)
    return None if st is None else str(getattr(st, "name", st))


def _floats_of(v: Any) -> list | None:
    """A 1-D float64 array's values as Python floats (``tolist``), else :func:`_as_list`."""
    if type(v) is np.ndarray and v.dtype is _FLOAT64 and v.ndim == 1:
        return v.tolist()
    return _as_list(v)


def _as_list(v: Any) -> list | None:
    if v is None:
        return None
    return [float(x) for x in np.asarray(v, dtype=float).reshape(-1)]
