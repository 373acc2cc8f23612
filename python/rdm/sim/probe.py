"""A logging node: samples named probes at its own rate into an MCAP log (json channels)."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

from rdm.sim.mcap_log import McapLogger


class ProbeNode:
    """Every ``period`` seconds, ``logger.log_json(topic, now, probe())`` for each probe.

    Probes read node state (counters, tables, outputs); they must not change it. A probe that
    returns None logs nothing that tick.
    """

    def __init__(
        self,
        logger: McapLogger,
        probes: Mapping[str, Callable[[], Mapping[str, Any] | None]],
        *,
        period: float = 0.01,
        name: str = "probe",
    ) -> None:
        self.logger = logger
        self.probes = dict(probes)
        self.period = period
        self.name = name

    def tick(self, now: float) -> None:
        for topic, probe in self.probes.items():
            values = probe()
            if values is not None:
                self.logger.log_json(topic, now, values)
