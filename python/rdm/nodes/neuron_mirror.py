"""One Neuron board on its own bus handle: a :class:`~rdm.nodes.neuron_bank.NeuronBankNode` of
one board (the same Rust core, ``rdm_core::firmware::neuron``; behaviour in that module).

For tools and tests that run one board per python-can bus, such as ``rdm neuron`` on SocketCAN
(``tests/vcan``): ``NeuronMirror(bus, slave_id, servos, imu=..., esc=...)`` reads and sets
like the board (``slave_id``, ``servos``, ``esc``, ``rx_errors``, ``set_imu``, ...).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import can

from rdm.protocol import neuron as nr
from rdm.protocol.neuron.ids import NEURON_SLAVE_IDS

from .neuron_bank import DEFAULT_REBOOT_MS, NeuronBankNode, NeuronBoardView, NeuronSpec
from .servo_model import ServoConfig

__all__ = ["DEFAULT_REBOOT_MS", "NeuronMirror"]


class NeuronMirror(NeuronBankNode):
    """One Neuron on ``bus`` with id ``slave_id`` (1..14) and up to four servos.

    ``plant_driven=True`` stops the built-in servo motion: a plant reads :meth:`servo_goals`
    and feeds back :meth:`set_present_positions` instead.
    """

    def __init__(
        self,
        bus: can.BusABC,
        slave_id: int,
        servos: Sequence[ServoConfig] = (),
        imu: bool = False,
        esc: bool = True,
        *,
        name: str | None = None,
        period: float = 0.001,
        plant_driven: bool = False,
        ttl_rs485_mixed: bool = False,
        pulley_skip_thresh: int = 0,
        reboot_ms: int = DEFAULT_REBOOT_MS,
    ) -> None:
        if not isinstance(slave_id, int) or slave_id not in NEURON_SLAVE_IDS:
            raise ValueError(f"NeuronMirror: slave_id {slave_id!r} not in 1..14")
        if len(servos) > nr.MAX_SERVO_NUM:
            raise ValueError(f"NeuronMirror: {len(servos)} servos > MAX_SERVO_NUM 4")
        name = name or f"neuron{slave_id}"
        spec = NeuronSpec(
            slave_id,
            tuple(servos),
            imu=imu,
            esc=esc,
            name=name,
            plant_driven=plant_driven,
            ttl_rs485_mixed=ttl_rs485_mixed,
            pulley_skip_thresh=pulley_skip_thresh,
            reboot_ms=reboot_ms,
        )
        super().__init__(bus, [spec], name=name, period=period)

    @property
    def board(self) -> NeuronBoardView:
        """The one board."""
        return self.boards[0]

    def __getattr__(self, attr: str) -> Any:
        # Only called for names the node itself lacks: the board's interface.
        if attr.startswith("__") or attr in ("boards", "_core"):
            raise AttributeError(attr)
        return getattr(self.boards[0], attr)
