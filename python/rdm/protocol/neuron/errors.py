"""The one exception every Neuron codec failure raises."""

from __future__ import annotations


class NeuronFrameError(ValueError):
    """A Neuron CAN frame (or frame field) is invalid.

    ``reason`` is a short machine-readable category used for counting:
    ``"dlc"``, ``"unknown_id"``, ``"range"``, ``"reserved_bits"``, ``"ambiguous"``,
    ``"not_standard_id"``, ``"remote"``, ``"direction"``.
    """

    def __init__(self, reason: str, message: str) -> None:
        super().__init__(f"{reason}: {message}")
        self.reason = reason
