"""Fuzz targets of every parser that takes bytes or text from outside the stack
(``docs/fuzzing.md``): each module lists its targets in ``TARGETS``; :data:`TARGETS` maps
every target's name to it. Import this package only where ``rdm`` may be imported (the
atheris engine imports it inside its coverage instrumentation)."""

from __future__ import annotations

from fuzz_targets import capture_index, description, ground, leptrino, neuron, rosserial
from fuzz_targets.base import Target

TARGETS: dict[str, Target] = {
    t.name: t
    for module in (rosserial, neuron, leptrino, capture_index, description, ground)
    for t in module.TARGETS
}
