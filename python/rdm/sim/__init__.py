"""Simulation support for ``rdm sim``: run folder, MCAP signal log, candump and UART captures,
metrics table and JSON summary, PNG plots. See docs/sim.md."""

from rdm.sim.candump import CandumpCapture
from rdm.sim.mcap_log import McapLogger, ros1_definition
from rdm.sim.metrics import Metric, format_metrics_table, summary_dict, write_summary
from rdm.sim.probe import ProbeNode
from rdm.sim.pty_pair import PtyPair, open_tapped_pty
from rdm.sim.run_folder import RunFolder

__all__ = [
    "CandumpCapture",
    "McapLogger",
    "Metric",
    "ProbeNode",
    "PtyPair",
    "RunFolder",
    "format_metrics_table",
    "open_tapped_pty",
    "ros1_definition",
    "summary_dict",
    "write_summary",
]
