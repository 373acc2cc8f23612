//! `rdm._rdm`: thin pyo3 bindings of `rdm_core`. Each concept registers its own classes
//! and functions from its own file; no algorithm lives in this crate.

use pyo3::prelude::*;

mod control;
mod errors;
mod estimate;
mod model;

#[pymodule]
fn _rdm(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    errors::register(m)?;
    model::register(m)?;
    estimate::register(m)?;
    control::register(m)?;
    Ok(())
}
