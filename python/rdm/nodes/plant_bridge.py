"""Plant bridge: couples the MuJoCo plant to the firmware mirrors once per millisecond.

Each ``tick(now)`` (the plant must be at ``now``; the lockstep scheduler steps it after the
nodes), in this order:

1. plant joint positions -> every Neuron's present positions (raw Dynamixel ticks): a snapshot
   of the joints at ``now`` that the bank converts when a board first reads it (a state
   report, torque-on, a config reply), so boards that report nothing cost nothing;
2. Neuron servo goals (servos with torque on) -> plant servo targets (rad), read only from
   Neurons whose change counter (goals, torque, ESC output) moved;
3. battery voltage -> plant ESCs and the battery sinks (the Spinal mirror's
   ``set_battery_voltage``); a change re-commands the duties (the plant converts a duty at the
   voltage of the moment it is commanded);
4. Neuron ESC outputs (duty 0.5..1, 0.5 while the watchdog stops the motor) -> plant rotor duties;
5. every ``imu_period``: one noisy plant IMU sample -> ``imu_sink(gyro, acc, mag)`` (the Spinal
   mirror's ``set_imu_sample``) and to Neurons that have an IMU;
6. every ``wrench_period``: one noisy sample per wrench sensor -> ``wrench_sinks[key](values)``,
   values = (Fx, Fy, Fz, Mx, My, Mz) (the Leptrino sensor node's ``set_wrench_values``);
7. every ``mocap_period``: foot pose -> ``mocap_sink(now, position, quaternion_wxyz)``;
   every ``truth_period``: ``truth_sink(GroundTruth)`` (the logger).

The bridge's state (the targets and duties last commanded, the battery voltage applied,
the sampling schedule, the time-mismatch count) and steps 1, 2 and 4 (the coupling of each
Neuron bank the boards belong to, ``rdm_core::firmware::bank_bridge``) live in one
:class:`rdm._rdm.PlantBridgeCore` (``_core``): this node forwards to it and runs the sinks,
and the lockstep kernel ticks the same object.

Commands flow mirror -> plant with one tick of delay (the mirrors tick after the bridge), as a
real PWM/servo update lands on the next control period.

The rotor <-> Neuron and joint <-> (Neuron, servo index) mapping is a :class:`BusLayout`;
:func:`default_layout` gives the RDM's (see docs/sim.md).
"""

from __future__ import annotations

import math
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from rdm import _rdm
from rdm.plant.description import RobotDescription

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

from .bus_layout import MAX_SERVOS_PER_NEURON, default_neuron_joints
from .servo_model import ServoConfig

#: Dynamixel X: 4096 ticks per revolution, 2048 = the centre (0 rad).
TICKS_PER_REV = 4096
CENTER_TICKS = 2048


@dataclass(frozen=True)
class NeuronLayout:
    """One Neuron board: its CAN slave id, the rotor its ESC drives, its servos in index order."""

    slave: int
    rotor: str | None
    joints: tuple[str, ...] = ()
    imu: bool = False


@dataclass(frozen=True)
class BusLayout:
    """Which Neuron drives which rotor and which joint servos, and the tick <-> rad map.

    ``ticks = center + sign * q * 4096 / (2 pi)`` per joint (``signs`` default +1).
    ``send_data_flag`` False marks a joint as a Spinal "gimbal" servo (no state on CAN).
    """

    neurons: tuple[NeuronLayout, ...]
    center_ticks: int = CENTER_TICKS
    ticks_per_rev: int = TICKS_PER_REV
    signs: dict[str, float] = field(default_factory=dict)
    no_state_joints: frozenset[str] = frozenset()

    def __post_init__(self) -> None:
        slaves = [n.slave for n in self.neurons]
        if len(set(slaves)) != len(slaves):
            raise ValueError(f"BusLayout: duplicate slave ids {slaves}")
        joints = [j for n in self.neurons for j in n.joints]
        if len(set(joints)) != len(joints):
            raise ValueError(f"BusLayout: a joint is mapped twice: {joints}")
        rotors = [n.rotor for n in self.neurons if n.rotor is not None]
        if len(set(rotors)) != len(rotors):
            raise ValueError(f"BusLayout: a rotor is mapped twice: {rotors}")
        for n in self.neurons:
            if not 1 <= n.slave <= 14:
                raise ValueError(f"BusLayout: slave id {n.slave} not in 1..14")
            if len(n.joints) > MAX_SERVOS_PER_NEURON:
                raise ValueError(f"BusLayout: Neuron {n.slave} has {len(n.joints)} servos > 4")

    def to_ticks(self, joint: str, q: float) -> float:
        """Raw ticks of ``joint`` at ``q`` rad (the servos' start positions)."""
        return self.center_ticks + q * layout_scale(self, joint)

    def servo_configs(self, slave: int, q0: dict[str, float] | None = None) -> list[ServoConfig]:
        """``ServoConfig`` list of one Neuron, starting at ``q0`` (rad, default 0)."""
        q0 = q0 or {}
        layout = next((n for n in self.neurons if n.slave == slave), None)
        if layout is None:
            raise KeyError(f"BusLayout: no Neuron {slave}")
        return [
            ServoConfig(
                dynamixel_id=i + 1,
                send_data_flag=joint not in self.no_state_joints,
                initial_position=min(
                    max(round(self.to_ticks(joint, q0.get(joint, 0.0))), 0), TICKS_PER_REV - 1
                ),
            )
            for i, joint in enumerate(layout.joints)
        ]


def _vectoring_units(desc: RobotDescription) -> list[dict]:
    with open(desc.toml_path, "rb") as f:
        return list(tomllib.load(f).get("vectoring_units", []))


def default_layout(desc: RobotDescription) -> BusLayout:
    """The default bus layout of a multilink robot description: the wiring rule of
    :func:`rdm.nodes.bus_layout.default_neuron_joints`; every servo reports its state
    (``send_data_flag``), so Spinal infers HYDRUS (16)."""
    table = default_neuron_joints(
        [r.name for r in desc.rotors], _vectoring_units(desc), desc.joint_order
    )
    return BusLayout(tuple(NeuronLayout(s, rotor, js) for s, (rotor, js) in table.items()))


def layout_scale(layout: BusLayout, joint: str) -> float:
    """Ticks per radian of ``joint`` (sign included)."""
    return layout.ticks_per_rev / (2.0 * math.pi) * layout.signs.get(joint, 1.0)


def _ratio(period: float | None, base: float, what: str) -> int:
    if period is None:
        return 0
    n = round(period / base)
    if n < 1 or abs(n * base - period) > 1e-9:
        raise ValueError(f"PlantBridge: {what} {period!r} is not a whole multiple of {base}")
    return n


class PlantBridge:
    """The 1 kHz coupling node between a :class:`rdm.plant.Plant` and the mirrors.

    Args:
        plant: the plant (stepped by the scheduler, not by the bridge).
        neurons: the Neuron mirrors (``plant_driven=True``), any order; matched by slave id.
        layout: the bus layout (default: :func:`default_layout` of the plant's description).
        battery_voltage: volts, constant or a function of simulated time.
        battery_sinks: called with the voltage when it changes.
        imu_sink: ``f(gyro, acc, mag)`` (rad/s, m/s^2, uT; IMU frame = Spinal's body frame).
        wrench_sinks: ``{sensor_key: f((Fx, Fy, Fz, Mx, My, Mz))}`` (N, N m, sensor frame).
        mocap_sink: ``f(now, position, quaternion_wxyz)`` of the foot frame.
        truth_sink: ``f(GroundTruth)``.
        truth_sink_touches: what ``truth_sink`` may change of the lockstep parts besides
            reading the plant (None: anything; ``()``: nothing, it only keeps or logs).
        *_period: seconds between calls (whole multiples of ``period``; None disables).

    The boards must be board views of :class:`rdm.nodes.neuron_bank.NeuronBankNode` banks
    (a :class:`rdm.nodes.neuron_mirror.NeuronMirror` is a bank of one board): the bridge
    attaches the coupling to each bank its boards belong to (:attr:`banks`, layout order).
    """

    #: Its part of the lockstep kernel (``rdm.nodes.lockstep_kernel.kind_of``); read from
    #: this class itself, so a subclass has only its Python tick unless it sets its own.
    lockstep_part: ClassVar[str] = "bridge"

    def __init__(
        self,
        plant,
        neurons: Sequence = (),
        layout: BusLayout | None = None,
        *,
        name: str = "plant_bridge",
        period: float = 0.001,
        battery_voltage: float | Callable[[float], float] = 23.0,
        battery_sinks: Sequence[Callable[[float], None]] = (),
        imu_sink: Callable[[np.ndarray, np.ndarray, np.ndarray], None] | None = None,
        imu_period: float | None = 0.005,
        wrench_sinks: dict[str, Callable[[tuple[float, ...]], None]] | None = None,
        wrench_period: float | None = 0.001,
        mocap_sink: Callable[[float, np.ndarray, np.ndarray], None] | None = None,
        mocap_period: float | None = 0.01,
        truth_sink: Callable[[object], None] | None = None,
        truth_period: float | None = 0.01,
        truth_sink_touches: Sequence[str] | None = None,
    ) -> None:
        self.plant = plant
        self.name = name
        self.period = period
        self.layout = layout or default_layout(plant.description)
        by_slave = {n.slave_id: n for n in neurons}
        joint_index = {j: i for i, j in enumerate(plant.joint_names)}
        rotor_index = {r: i for i, r in enumerate(plant.rotor_names)}
        # (neuron, [(servo index, joint index, joint name)])
        self._servo_map: list[tuple[object, list[tuple[int, int, str]]]] = []
        self._rotor_map: list[tuple[int, object]] = []
        for nl in self.layout.neurons:
            neuron = by_slave.get(nl.slave)
            if neuron is None:
                raise ValueError(f"PlantBridge: no Neuron mirror with slave id {nl.slave}")
            if not callable(getattr(getattr(neuron, "_bank", None), "attach_bridge", None)):
                raise ValueError(
                    f"PlantBridge: Neuron {nl.slave} is not a board of a NeuronBankNode"
                )
            if len(neuron.servos) != len(nl.joints):
                raise ValueError(
                    f"PlantBridge: Neuron {nl.slave} has {len(neuron.servos)} servos, layout "
                    f"maps {len(nl.joints)}"
                )
            for joint in nl.joints:
                if joint not in joint_index:
                    raise ValueError(f"PlantBridge: layout joint {joint!r} not in the plant")
            self._servo_map.append(
                (neuron, [(i, joint_index[j], j) for i, j in enumerate(nl.joints)])
            )
            if nl.rotor is not None:
                if nl.rotor not in rotor_index:
                    raise ValueError(f"PlantBridge: layout rotor {nl.rotor!r} not in the plant")
                self._rotor_map.append((rotor_index[nl.rotor], neuron))
        self._imu_neurons = [by_slave[n.slave] for n in self.layout.neurons if n.imu]
        self._battery_sinks = list(battery_sinks)
        self._imu_sink = imu_sink
        self._wrench_sinks = dict(wrench_sinks or {})
        for key in self._wrench_sinks:
            if key not in plant.wrench_models:
                raise ValueError(f"PlantBridge: plant has no wrench sensor {key!r}")
        self._mocap_sink = mocap_sink
        self._truth_sink = truth_sink
        #: What the truth sink may change besides reading the plant, by lockstep part name
        #: (``rdm.nodes.lockstep_kernel``: "bridge", "bank", "spinal", "leptrino"); None:
        #: anything.
        self.truth_sink_touches = None if truth_sink_touches is None else tuple(truth_sink_touches)
        # Ticks between samples (0: off; each reading is taken on the first tick, then every
        # n-th). The one schedule of both the Python tick and the lockstep kernel's.
        imu_n = _ratio(imu_period, period, "imu_period")
        wrench_n = _ratio(wrench_period, period, "wrench_period")
        mocap_n = _ratio(mocap_period, period, "mocap_period")
        truth_n = _ratio(truth_period, period, "truth_period")
        #: The sampling schedule (the core's).
        self.schedule = _rdm.SampleSchedule(
            imu_n if imu_sink is not None or self._imu_neurons else 0,
            wrench_n if self._wrench_sinks else 0,
            mocap_n if mocap_sink is not None else 0,
            truth_n if truth_sink is not None else 0,
        )
        #: The Neuron banks the coupling runs in (each holds its boards' part), layout order.
        self.banks: list = []
        self._attach_banks()
        self._core = _rdm.PlantBridgeCore(
            [float(q) for q in plant.servo_positions()],
            len(plant.rotor_names),
            period,
            self.schedule,
            [bank._core for bank in self.banks],
        )
        self._battery: float | Callable[[float], float] = 23.0
        self.set_battery(battery_voltage)
        self._foot_body = plant.model.body(plant.description.foot_frame).id

    def _attach_banks(self) -> None:
        """Attach each bank's part of the coupling (``NeuronBankNode.attach_bridge``): its
        servos ``(board, servo, joint)``, rotors ``(rotor, board)`` and boards in layout order,
        with the plant's qpos addresses and the layout's ticks per radian per joint."""
        names = self.plant.joint_names
        scale = [layout_scale(self.layout, j) for j in names]
        qadr = np.asarray(self.plant._qadr).tolist()
        parts: dict[int, tuple[object, list, list, list]] = {}
        for neuron, entries in self._servo_map:
            bank, servos, _, boards = parts.setdefault(id(neuron._bank), (neuron._bank, [], [], []))
            servos.extend((neuron._k, i, k) for i, k, _ in entries)
            boards.append(neuron._k)
        for r, neuron in self._rotor_map:
            bank = neuron._bank
            parts.setdefault(id(bank), (bank, [], [], []))[2].append((r, neuron._k))
        for bank, servos, rotors, boards in parts.values():
            bank.attach_bridge(self.layout.center_ticks, qadr, scale, servos, rotors, boards)
            self.banks.append(bank)
        #: joint index -> the bank whose board drives its servo
        self._joint_bank = {
            k: neuron._bank for neuron, entries in self._servo_map for _, k, _ in entries
        }

    def tick(self, now: float) -> None:
        """Couple plant and mirrors at ``now`` (see the module doc)."""
        self._couple(now)
        self._sample(now)

    def _couple(self, now: float) -> None:
        """Steps 1-4: the core counts a time mismatch, each bank snapshots the joints and
        writes its changed goals and ESC outputs into the core's targets and duties; the
        plant is commanded when they moved, the targets before the battery voltage and the
        voltage before the duties (the plant converts a duty at the voltage it holds when
        commanded)."""
        plant, core = self.plant, self._core
        targets_changed, duties_changed = core.couple(plant.time, now, plant._v_qpos)
        if targets_changed:
            plant.set_servo_targets(core.targets)
        if self._apply_battery(now) or duties_changed:
            plant.set_rotor_duties(core.duties)

    def stick_servo(self, joint: str) -> None:
        """Fault hook (``rdm sim mission --fault stuck-servo``): the servo of ``joint`` stops
        following its goal, its shaft held where it is (``NeuronBankNode.stick_joint`` of the
        bank that drives it); its Neuron still reports the true (stuck) position."""
        names = list(self.plant.joint_names)
        k = names.index(joint) if joint in names else -1
        if k not in self._joint_bank:
            raise ValueError(f"stick_servo: joint {joint!r} not one of {', '.join(names)}")
        self._joint_bank[k].stick_joint(k)

    def set_battery(self, volts: float | Callable[[float], float]) -> None:
        """The battery voltage from now on (volts, or a function of simulated time): the
        plant's ESCs and the battery sinks take it at the next tick."""
        self._battery = volts
        self._core.set_fixed_battery(None if callable(volts) else float(volts))

    def _apply_battery(self, now: float) -> bool:
        """Apply the battery voltage of ``now`` if it changed (plant ESCs, then the sinks);
        True if it did: the duties must be re-commanded."""
        volts = self._battery(now) if callable(self._battery) else self._battery
        if not self._core.apply_voltage(volts):
            return False
        self.plant.set_battery_voltage(volts)
        for sink in self._battery_sinks:
            sink(volts)
        return True

    def _sample(self, now: float) -> None:
        """Steps 5-7: the readings due at ``now``."""
        plant = self.plant
        imu, wrench, mocap, truth = self.schedule.advance()
        if imu:
            r = plant.imu()
            if self._imu_sink is not None:
                self._imu_sink(r.gyro, r.accel, r.mag)
            for neuron in self._imu_neurons:
                neuron.set_imu(r.gyro, r.accel, r.mag)
        if wrench:
            for key, sink in self._wrench_sinks.items():
                sink(plant.wrench_values(key))
        if mocap:
            d = plant.data
            self._mocap_sink(now, d.xpos[self._foot_body].copy(), d.xquat[self._foot_body].copy())
        if truth:
            self._truth_sink(plant.ground_truth())

    @property
    def time_mismatches(self) -> int:
        """Ticks that found the plant more than half a period away from the tick's time."""
        return self._core.time_mismatches

    @property
    def ticks(self) -> int:
        """Ticks taken so far (the sampling schedule counts them)."""
        return self.schedule.count

    @property
    def battery_voltage(self) -> float | None:
        """The last voltage applied."""
        return self._core.voltage
