"""Simulation support for ``rdm sim``: run folder, MCAP signal log, candump and UART captures,
metrics table and JSON summary, PNG plots. See docs/sim.md."""

from rdm.sim.candump import CandumpCapture
from rdm.sim.mcap_log import McapLogger, ros1_definition
from rdm.sim.metrics import Metric, format_metrics_table, summary_dict, write_summary
from rdm.sim.probe import ProbeNode
from rdm.sim.run_folder import RunFolder
from rdm.sim.uart import PtyPair, TappedLink, open_inproc_uart, open_tapped_pty

__all__ = [
    "CandumpCapture",
    "McapLogger",
    "Metric",
    "ProbeNode",
    "PtyPair",
    "RunFolder",
    "TappedLink",
    "format_metrics_table",
    "open_inproc_uart",
    "open_tapped_pty",
    "ros1_definition",
    "summary_dict",
    "write_summary",
]
