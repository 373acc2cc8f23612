"""The fast parts of the lockstep loop (:class:`rdm._rdm.LockstepKernel`, behind :class:`Lockstep`).

:func:`attach_kernel` gives the loop's kernel the fast parts its nodes allow: the routine
milliseconds of the simulated firmware side (plant bridge, Neuron bank, Spinal's idle, boot
and routine busy ms, Leptrino streaming, the plant step) then run in Rust on the cores the
Python nodes already use, at the same base ticks in the same order. Every other tick is the
node's own Python ``tick``. Before Python code runs, the kernel writes back what its fast
ticks changed of the parts that code may read or change; after, it re-reads those parts'
plans. State that is one Rust object the node and the kernel share (the Leptrino stream,
the Neuron bank, the plant's state and foot contact tracker, the resting sleep, the noise
models' normal streams) needs neither: only
the Leptrino's pending UART bytes wait. So the logs are the same bytes as with every tick
in Python (tests/test_lockstep_kernel.py, tests/test_spinal_kernel_busy.py; docs/sim.md).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from rdm import _rdm
from rdm.link.can_wire import DRAIN_AT, CanWireLink
from rdm.link.tapped_link import TappedLink
from rdm.link.uart_pipe import InProcessUartEnd

from .lockstep import Lockstep
from .plant_bridge import PlantBridge


def kind_of(node: Any) -> str | None:
    """The fast path a node of this class can have: its class's own ``lockstep_part``
    ("bridge", "bank", "spinal", "leptrino"; not inherited), None: only its Python tick."""
    return type(node).__dict__.get("lockstep_part")


def _attach_plant(kernel: _rdm.LockstepKernel, plant: Any) -> None:
    """Hand the kernel the plant's parts it holds for the plant's lifetime (typed values:
    the plant's step, state and rotor cores, the MjData views and the servo actuators)."""
    kernel.attach_plant(
        plant._stepper,
        plant._state,
        plant._rotors,
        plant._v_qpos,
        plant._v_sensordata,
        plant._v_ctrl,
        [int(a) for a in plant._servo_act],
    )


def _bridge_plan(bridge: PlantBridge, leptrino: Any, spinal: Any) -> Callable[[], tuple | None]:
    """The sample paths the kernel reads for ``bridge`` (called again after Python code
    ran): None when its tick has no Rust form now (a wrench sink other than ``leptrino``'s
    ``set_wrench_values``), else the foot wrench path (addresses, noise core, normal stream),
    the IMU path when its only sink is ``spinal``'s
    ``set_imu_sample`` (else None: an IMU ms is Python's), the truth call and the parts it
    may change. Mocap samples are Python's. The bridge's state (counters, schedule, targets,
    duties, battery) is its ``_core``, the one object both tick forms use; the kernel ticks
    it only while its battery is a constant already applied."""
    plant = bridge.plant
    cls = type(plant)

    def truth() -> None:
        bridge._truth_sink(plant.ground_truth())

    def plan() -> tuple | None:
        b = bridge
        imu_on, wrench_on, _, truth_on = (n > 0 for n in b.schedule.every)
        adr, core, normals = (0, 0), None, None
        if wrench_on:
            if len(b._wrench_sinks) != 1 or leptrino is None:
                return None
            ((key, sink),) = b._wrench_sinks.items()
            if getattr(sink, "__self__", None) is not leptrino:
                return None
            if getattr(sink, "__name__", "") != "set_wrench_values":
                return None
            if getattr(plant.wrench_values, "__func__", None) is not cls.wrench_values:
                return None
            model = plant.wrench_models[key]
            adr, core, normals = plant._wrench_adr[key], model._core, model._normals
        imu = None
        sink = b._imu_sink
        if (
            imu_on
            and not b._imu_neurons
            and spinal is not None
            and getattr(sink, "__self__", None) is spinal
            and getattr(sink, "__name__", "") == "set_imu_sample"
            and getattr(plant.imu, "__func__", None) is cls.imu
        ):
            model = plant.imu_model
            imu = (plant._imu_adr, model._core, model._normals, spinal._state)
        touches = b.truth_sink_touches
        return (
            adr,
            core,
            normals,
            imu,
            truth if truth_on else None,
            ["plant", "bridge", "bank", "spinal", "leptrino"]
            if touches is None
            else ["plant", *touches],
        )

    return plan


def _leptrino_uart(node: Any) -> tuple[Callable[[], bool], Callable[..., int]]:
    """``(idle, write)`` of the Leptrino node's UART for the kernel: ``idle()``, whether its
    streaming tick can run in the kernel now (the UART is the one it had at attach, a
    :class:`TappedLink` over an open :class:`InProcessUartEnd` with an open peer, so every
    write is whole, and no host bytes wait: a command is answered first, in Python);
    ``write``, that link's ``write_marked``."""
    uart = node.uart
    write = getattr(uart, "write_marked", None)
    if type(uart) is not TappedLink or type(uart.link) is not InProcessUartEnd or write is None:
        return (lambda: False), (lambda data, marks: 0)
    end = uart.link

    def idle() -> bool:
        peer = end.peer
        return node.uart is uart and not (end.inbox or end.closed or peer is None or peer.closed)

    return idle, write


def attach_kernel(loop: Lockstep, plant: Any | None = None) -> _rdm.LockstepKernel:
    """Give ``loop``'s kernel (``loop.kernel``) the fast parts its nodes allow: ``plant`` (an
    :class:`rdm.plant.Plant`, the loop's physics) steps in the kernel; a :class:`PlantBridge`
    on that plant (its ``_core``), a :class:`NeuronBankNode` on a :class:`CanWireLink`, a
    :class:`SpinalMirror` whose Rust master ticks on that wire and a
    :class:`LeptrinoSensorNode` get their steady ticks run there. After any other node's
    Python tick every part is flushed and every plan re-read, unless the node (its class or
    the instance) declares what it may read or change in ``kernel_touches`` (part names:
    "plant", "bridge", "bank", "spinal", "leptrino"; e.g. the mocap node reads the plant, the
    onboard node writes into the Spinal and reads the Leptrino UART, a scenario script
    declares its own). Returns the kernel."""
    nodes = loop.nodes
    kernel = loop.kernel
    if plant is not None and plant is loop.physics:
        _attach_plant(kernel, plant)
    leptrino = spinal = None
    for i, node in enumerate(nodes):
        kind = kind_of(node)
        if kind == "leptrino":
            if leptrino is None:
                kernel.attach_leptrino(i, node._stream, *_leptrino_uart(node))
                leptrino = node
        elif kind == "bank" and isinstance(node._wire, CanWireLink):
            kernel.attach_bank(i, node._core, node._wire.wire)
        elif kind == "spinal" and node._wire_link is not None and spinal is None:
            kernel.attach_spinal(
                i, node, node._state, node.master.core, node._wire_link.wire, DRAIN_AT
            )
            spinal = node
    for i, node in enumerate(nodes):
        touches = getattr(node, "kernel_touches", None)
        if touches is not None and kind_of(node) is None:
            kernel.set_touches(i, list(touches))
    for i, node in enumerate(nodes):
        if kind_of(node) == "bridge" and plant is node.plant and plant is loop.physics:
            kernel.attach_bridge(i, node._core, _bridge_plan(node, leptrino, spinal))
    return kernel
