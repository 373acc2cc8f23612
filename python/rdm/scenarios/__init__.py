"""The paper's experiments on the simulated robot with every byte on its wire (``rdm sim``)."""

from .registry import DEFAULT_SCENARIO, SCENARIOS

__all__ = ["DEFAULT_SCENARIO", "SCENARIOS"]
