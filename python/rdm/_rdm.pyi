"""Type stubs of the compiled core :mod:`rdm._rdm` (see crates/rdm_py)."""

__version__: str

class RdmError(ValueError):
    """Base class of every error raised by rdm's core."""
