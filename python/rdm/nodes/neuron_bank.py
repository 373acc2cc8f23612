"""All Neuron boards of one CAN bus in one node, run by the Rust core (``rdm._rdm.NeuronBank``,
``rdm_core::firmware::neuron``; fact sheet sec. 2).

What the firmware does each millisecond, per board: drop frames whose slave field is neither
15 nor its own id (the hardware filter, counted in ``rx_filtered``); answer ENUM_REQUEST and
INITIAL_CONFIG_REQUEST (CONFIG_0, then CONFIG_1/2/3 per servo); apply BOARD_CONFIG
sub-commands (answered with the full config set; REBOOT takes ``reboot_ms``); read its PWM slot;
apply servo goal / current / torque words; after a servo-angle frame send the state of every
servo with ``send_data_flag``, then gyro, acc, mag if its IMU flag is set; move the servos
(unless a plant drives them); stop the ESC after 100 ms without an accepted frame (the
watchdog). Bad frames (DLC, reserved bits, direction, extended/remote/FD) are counted in
``rx_errors`` by reason and ignored.

The bank drains its bus once per tick, hands every frame to the core in one call and sends
the core's replies through the same python-can bus (or, given a
:class:`rdm.link.can_wire.CanWireLink`, straight onto the Rust wire). Boards of one bank hear
each other's frames as boards on one bus do (colliding slave ids).

:attr:`NeuronBankNode.boards` holds one :class:`NeuronBoardView` per board with the part of
the mirror interface the plant bridge, the stack and the tools use (``slave_id``,
``servos[i].goal / torque_enable``, ``change_count``, ``esc.duty``, ``set_imu`` ...).
"""

from __future__ import annotations

import dataclasses
import math
from collections import Counter
from collections.abc import Sequence
from typing import Any, ClassVar

import can

from rdm import _rdm
from rdm.link.can import send_neuron_payload
from rdm.link.can_wire import CanWireLink
from rdm.protocol import neuron as nr

from .base import drain
from .esc_model import EscOutputs
from .servo_model import ServoConfig

_SENSORS = (nr.ImuMessage.GYRO, nr.ImuMessage.ACC, nr.ImuMessage.MAG)
#: Simulated reboot time after BOARD_CONFIG REBOOT (ASSUMPTION: the real one is a reset + init).
DEFAULT_REBOOT_MS = 100

_IMU_SCALE = {
    nr.ImuMessage.GYRO: nr.GYRO_SCALE,
    nr.ImuMessage.ACC: nr.ACC_SCALE,
    nr.ImuMessage.MAG: nr.MAG_SCALE,
}


def _int16(value: float) -> int:
    return int(min(max(round(value), -0x8000), 0x7FFF))


def _finite_xyz(sensor: nr.ImuMessage, xyz: Sequence[float]) -> tuple[float, float, float]:
    if len(xyz) != 3 or not all(math.isfinite(v) for v in xyz):
        raise ValueError(f"{sensor.name.lower()}: need 3 finite values, got {xyz!r}")
    return float(xyz[0]), float(xyz[1]), float(xyz[2])


def _int16_xyz(sensor: nr.ImuMessage, xyz: Sequence[int]) -> tuple[int, int, int]:
    if len(xyz) != 3 or not all(isinstance(v, int) and -0x8000 <= v <= 0x7FFF for v in xyz):
        raise ValueError(f"{sensor.name.lower()}: need 3 int16 values, got {xyz!r}")
    return int(xyz[0]), int(xyz[1]), int(xyz[2])


@dataclasses.dataclass(frozen=True)
class NeuronSpec:
    """One board of a bank: its slave id, servos, IMU and ESC flags, options."""

    slave_id: int
    servos: tuple[ServoConfig, ...] = ()
    imu: bool = False
    esc: bool = True
    name: str | None = None
    plant_driven: bool = False
    ttl_rs485_mixed: bool = False
    pulley_skip_thresh: int = 0
    reboot_ms: int = DEFAULT_REBOOT_MS

    def core_dict(self) -> dict[str, Any]:
        return {
            "slave_id": self.slave_id,
            "servos": [dataclasses.asdict(c) for c in self.servos],
            "imu": self.imu,
            "esc": self.esc,
            "plant_driven": self.plant_driven,
            "ttl_rs485_mixed": self.ttl_rs485_mixed,
            "pulley_skip_thresh": self.pulley_skip_thresh,
            "reboot_ms": self.reboot_ms,
        }


class EscView(EscOutputs):
    """A board's ESC: the slot value it holds and the watchdog's verdict (read from the core)."""

    __slots__ = ("_board",)

    def __init__(self, board: NeuronBoardView) -> None:
        self._board = board

    @property
    def held_value(self) -> int:
        return self._board._bank._core.esc(self._board._k)[0]

    @held_value.setter
    def held_value(self, value: int) -> None:
        self._board._bank._core.set_esc_held_value(self._board._k, value)

    @property
    def stopped(self) -> bool:
        return self._board._bank._core.esc(self._board._k)[1]

    @property
    def value(self) -> int:
        """What the timer outputs now, 0..1000 (``pulse_us - 1000``)."""
        held, stopped = self._board._bank._core.esc(self._board._k)
        return nr.pwm.PWM_STOP_VALUE if stopped else held


class ServoView:
    """One servo of a board (read from the core)."""

    __slots__ = ("_board", "_i")

    def __init__(self, board: NeuronBoardView, index: int) -> None:
        self._board = board
        self._i = index

    def _state(self) -> dict[str, Any]:
        return self._board.state()["servos"][self._i]

    @property
    def goal(self) -> int:
        return self._board._outputs()[0][self._i]

    @property
    def torque_enable(self) -> bool:
        return self._board._outputs()[1][self._i]

    @property
    def position(self) -> float:
        return self._state()["position"]

    @property
    def present_position(self) -> int:
        return self._state()["present_position"]

    @property
    def send_goal_position(self) -> bool:
        return self._state()["send_goal_position"]

    @property
    def goal_current(self) -> int:
        return self._state()["goal_current"]

    @property
    def current(self) -> int:
        return self._state()["current"]

    @property
    def moving(self) -> bool:
        return self._state()["moving"]

    @property
    def hardware_error(self) -> int:
        return self._state()["hardware_error"]

    @hardware_error.setter
    def hardware_error(self, value: int) -> None:
        self._board._bank._core.set_servo_field(self._board._k, self._i, "hardware_error", value)

    @property
    def temperature(self) -> int:
        """The temperature the servo reports [deg C]."""
        return self._state()["temperature"]

    @temperature.setter
    def temperature(self, value: int) -> None:
        self._board._bank._core.set_servo_field(self._board._k, self._i, "temperature", value)

    def set_external_current(self, value: int | None) -> None:
        """When set, the reported current (else the position-error model)."""
        self._board._bank._core.set_servo_field(self._board._k, self._i, "external_current", value)


class NeuronBoardView:
    """One board of a :class:`NeuronBankNode`: what a plant, the stack and the tools read and
    set (``slave_id``, ``servos[i].goal / torque_enable``, ``change_count``, ``esc.duty``,
    ``set_imu`` ...)."""

    def __init__(self, bank: NeuronBankNode, k: int, spec: NeuronSpec) -> None:
        self._bank = bank
        self._k = k
        self.name = spec.name or f"neuron{spec.slave_id}"
        self.period = bank.period
        self.has_esc = spec.esc
        self.plant_driven = spec.plant_driven
        self.servos = [ServoView(self, i) for i in range(len(spec.servos))]
        self.esc = EscView(self)
        self._outputs_at = -1
        self._outputs_cache: tuple[list[int], list[bool]] = ([], [])

    @property
    def change_count(self) -> int:
        """The core's change counter of this board (bumped by goal / torque / ESC output
        changes)."""
        return self._bank._core.board_changes(self._k)

    @property
    def tx_count(self) -> int:
        """Frames this board sent on its bus (counted by the core)."""
        return self._bank._core.tx_count(self._k)[0]

    @property
    def tx_errors(self) -> int:
        """Frames of this board its bus refused."""
        return self._bank._core.tx_count(self._k)[1]

    def _outputs(self) -> tuple[list[int], list[bool]]:
        c = self.change_count
        if c != self._outputs_at:
            self._outputs_cache = self._bank._core.servo_outputs(self._k)
            self._outputs_at = c
        return self._outputs_cache

    def power_cycle(self) -> None:
        """Fault hook: this board's MCU resets at the call (``_rdm.NeuronBank.power_cycle``)."""
        self._bank._core.power_cycle(self._k)
        self._outputs_at = -1  # read again

    def state(self) -> dict[str, Any]:
        """Everything the core holds about this board (see ``NeuronBank.board_state``)."""
        return self._bank._core.board_state(self._k)

    @property
    def slave_id(self) -> int:
        return self.state()["slave_id"]

    @property
    def flash_slave_id(self) -> int:
        return self.state()["flash_slave_id"]

    @property
    def imu_send_flag(self) -> bool:
        return self.state()["imu_send_flag"]

    @property
    def connected(self) -> bool:
        return self.state()["connected"]

    @property
    def rx_count(self) -> int:
        return self.state()["rx_count"]

    @property
    def rx_filtered(self) -> int:
        return self.state()["rx_filtered"]

    @property
    def rx_errors(self) -> Counter[str]:
        return Counter(self.state()["rx_errors"])

    @property
    def rx_kinds(self) -> Counter[str]:
        return Counter(self.state()["rx_kinds"])

    @property
    def reboots(self) -> int:
        return self.state()["reboots"]

    @property
    def imu_raw(self) -> dict[nr.ImuMessage, tuple[int, int, int]]:
        raw = self._bank._core.imu_raw(self._k)
        return {s: tuple(raw[int(s)]) for s in _SENSORS}  # type: ignore[misc]

    def servo_goals(self) -> list[int]:
        """Goal positions (raw ticks) the servos are commanded to, in index order."""
        return list(self._outputs()[0])

    def set_present_positions(self, positions: Sequence[float]) -> None:
        """Plant feedback of the joint positions (raw ticks), in index order."""
        if len(positions) != len(self.servos):
            raise ValueError(f"{self.name}: {len(positions)} positions for {len(self.servos)}")
        n = len(self.servos)
        self._bank._core.set_positions([self._k] * n, list(range(n)), [float(p) for p in positions])

    def set_imu_raw(
        self,
        gyro: Sequence[int] | None = None,
        acc: Sequence[int] | None = None,
        mag: Sequence[int] | None = None,
    ) -> None:
        """Raw MPU9250/AK8963 int16 samples in the sensor frame (what goes on CAN)."""
        for sensor, xyz in zip(_SENSORS, (gyro, acc, mag), strict=True):
            if xyz is not None:
                raw = _int16_xyz(sensor, xyz)
                self._bank._core.set_imu_raw(self._k, int(sensor), list(raw))

    def set_imu(
        self,
        gyro: Sequence[float] | None = None,
        acc: Sequence[float] | None = None,
        mag: Sequence[float] | None = None,
    ) -> None:
        """Physical values in Spinal's frame (rad/s, m/s^2, uT), converted to raw samples by
        inverting Spinal's scaling and axis remap (rounded, saturated to int16)."""
        core = self._bank._core
        for sensor, xyz in ((nr.ImuMessage.GYRO, gyro), (nr.ImuMessage.ACC, acc)):
            if xyz is not None:
                sx, sy, sz = _finite_xyz(sensor, xyz)
                k = _IMU_SCALE[sensor]
                # Spinal: (x, y, z) = (-raw_y, raw_x, raw_z) * k
                core.set_imu_raw(
                    self._k, int(sensor), [_int16(sy / k), _int16(-sx / k), _int16(sz / k)]
                )
        if mag is not None:
            sx, sy, sz = _finite_xyz(nr.ImuMessage.MAG, mag)
            k = nr.MAG_SCALE
            # Spinal: (x, y, z) = (-raw_x, raw_y, -raw_z) * k
            core.set_imu_raw(self._k, 2, [_int16(-sx / k), _int16(sy / k), _int16(-sz / k)])

    def close(self) -> None:
        """The bank owns the bus (:meth:`NeuronBankNode.close`)."""


class NeuronBankNode:
    """Every Neuron of ``bus`` (the boards of ``specs``, ticked in that order) as one 1 kHz
    node; the board views are :attr:`boards`."""

    #: Its part of the lockstep kernel (``rdm.nodes.lockstep_kernel.kind_of``); read from
    #: this class itself, so a subclass has only its Python tick unless it sets its own.
    lockstep_part: ClassVar[str] = "bank"

    def __init__(
        self,
        bus: can.BusABC,
        specs: Sequence[NeuronSpec],
        *,
        name: str = "neurons",
        period: float = 0.001,
    ) -> None:
        self.bus = bus
        #: Given a :class:`rdm.link.can_wire.CanWireLink` instead of a bus: the Rust wire.
        self._wire = bus if isinstance(bus, CanWireLink) else None
        self.name = name
        self.period = period
        self._core = _rdm.NeuronBank([s.core_dict() for s in specs])
        self.boards = [NeuronBoardView(self, k, s) for k, s in enumerate(specs)]

    def attach_bridge(
        self,
        center: int,
        qadr: Sequence[int],
        scale: Sequence[float],
        servos: Sequence[tuple[int, int, int]],
        rotors: Sequence[tuple[int, int]],
        group_boards: Sequence[int],
    ) -> None:
        """Run the plant bridge's per-millisecond coupling in the core (``NeuronBank.
        attach_bridge``; see :class:`rdm.nodes.plant_bridge.PlantBridge`): the present positions
        of the bridge's last snapshot are pushed when the boards need them."""
        self._core.attach_bridge(
            int(center), list(qadr), list(scale), list(servos), list(rotors), list(group_boards)
        )

    def stick_joint(self, joint: int) -> None:
        """Fault hook: joint ``joint``'s servo output stops following its goal (the
        attached coupling's ``_rdm.NeuronBank.stick_joint``)."""
        self._core.stick_joint(joint)

    def tick(self, now: float) -> None:
        """Drain the bus, run every board at ``now``, send their frames in order."""
        if self._wire is not None:  # the Rust wire to the Rust master (docs/canbus.md)
            # the core pushes the bridge's positions when a frame reads them, counts the sent
            # frames (the lockstep kernel makes the same call)
            self._core.tick_wire(now, self._wire.clock(), self._wire.wire)
            return
        out = self._core.tick(now, list(drain(self.bus)))
        if out:
            bus, core = self.bus, self._core
            for k, can_id, payload in out:
                core.count_tx(k, send_neuron_payload(bus, can_id, payload))

    def close(self) -> None:
        """Shut the bus down (the node owns it)."""
        self.bus.shutdown()
