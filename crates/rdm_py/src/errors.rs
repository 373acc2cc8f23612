//! Python exception types raised by the bindings.

use pyo3::create_exception;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

create_exception!(
    _rdm,
    RdmError,
    PyValueError,
    "Base class of every error raised by rdm's core."
);

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("RdmError", m.py().get_type::<RdmError>())?;
    Ok(())
}
