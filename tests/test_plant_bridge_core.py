"""The plant bridge's one state object (``_rdm.PlantBridgeCore``, held by ``PlantBridge._core``):
the battery voltage applied on change only, the time-mismatch count, and the refusal of a bad
period. Oracles: the written-out voltage sequence of the battery function, the plant's own ESC
voltage, and the half-period rule evaluated by hand."""

from __future__ import annotations

import pytest

from rdm import _rdm
from rdm.link.inproc_can import InProcessBus
from rdm.nodes.neuron_bank import NeuronBankNode, NeuronSpec
from rdm.nodes.plant_bridge import PlantBridge, default_layout
from rdm.plant import Plant


def _bridge(name: str, **kwargs) -> tuple[PlantBridge, NeuronBankNode, Plant]:
    plant = Plant("rdm", seed=1, fixed_base=True, ceiling_height=None)
    layout = default_layout(plant.description)
    specs = [
        NeuronSpec(nl.slave, tuple(layout.servo_configs(nl.slave)), plant_driven=True)
        for nl in layout.neurons
    ]
    bank = NeuronBankNode(InProcessBus(name), specs)
    kwargs.setdefault("imu_period", None)
    kwargs.setdefault("wrench_period", None)
    kwargs.setdefault("mocap_period", None)
    kwargs.setdefault("truth_period", None)
    return PlantBridge(plant, bank.boards, **kwargs), bank, plant


def test_battery_reaches_plant_and_sinks_once_per_change() -> None:
    volts: list[float] = []
    bridge, bank, plant = _bridge(
        "core_battery", battery_voltage=23.0, battery_sinks=[volts.append]
    )
    try:
        assert bridge.battery_voltage is None and not bridge._core.battery_steady
        for _ in range(3):
            bridge.tick(0.0)  # the plant stays at 0 s: every tick at its time
        assert volts == [23.0] and bridge._core.battery_steady
        # a function of time: a tick per value, applied when it changes only
        bridge.set_battery(lambda t: 24.0 if t < 0.5 else 22.5)
        assert not bridge._core.battery_steady
        for now in (0.0, 0.0, 0.0):
            bridge.tick(now)
        assert volts == [23.0, 24.0]
        assert plant.escs[0].voltage == 24.0
        bridge.set_battery(22.5)  # the constant differs from the last applied: once more
        assert not bridge._core.battery_steady
        bridge.tick(0.0)
        bridge.tick(0.0)
        assert volts == [23.0, 24.0, 22.5] and bridge._core.battery_steady
        assert bridge.battery_voltage == 22.5
        assert [e.voltage for e in plant.escs] == [22.5] * len(plant.escs)
    finally:
        bank.close()


def test_time_mismatch_counts_ticks_beyond_half_a_period() -> None:
    bridge, bank, plant = _bridge("core_time")
    try:
        assert plant.time == 0.0
        # |plant.time - now| > 0.0005 counts: 0.0004 no, 0.0006 yes, -0.002 yes, 0 no
        for now in (0.0004, 0.0006, -0.002, 0.0):
            bridge.tick(now)
        assert bridge.time_mismatches == 2
        assert bridge.ticks == 4
    finally:
        bank.close()


@pytest.mark.parametrize("period", [0.0, -0.001, float("nan")])
def test_core_refuses_a_bad_period(period: float) -> None:
    with pytest.raises(ValueError, match="period"):
        _rdm.PlantBridgeCore([], 0, period, _rdm.SampleSchedule(0, 0, 0, 0), [])
