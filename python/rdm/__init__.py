"""rdm: control, planning and hardware-in-the-loop stack for rotor-distributed manipulators.

The Rust core is exposed as :mod:`rdm._rdm`; the pure-Python layers (wire protocols,
transports, nodes) import it only where they need it, so that protocol tools work even
in an environment where the extension is being rebuilt.
"""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("rdm")
except PackageNotFoundError:  # running from a source tree without installation
    __version__ = "0.0.0+source"

__all__ = ["__version__"]
