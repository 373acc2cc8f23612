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
create_exception!(
    _rdm,
    DescriptionError,
    RdmError,
    "A robot description (URDF/TOML) is malformed or inconsistent; the message names the file and field."
);
create_exception!(
    _rdm,
    ModelError,
    RdmError,
    "Bad input to a model evaluation (wrong length, NaN, unknown frame); the message names the argument."
);

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("RdmError", m.py().get_type::<RdmError>())?;
    m.add("DescriptionError", m.py().get_type::<DescriptionError>())?;
    m.add("ModelError", m.py().get_type::<ModelError>())?;
    Ok(())
}
