//! Binding of `rdm_core::sim::python_float_repr`: the body of a JSON float array written as
//! Python's `json.dumps` writes it, for the run logger's 100 Hz JSON records
//! (`rdm.sim.mcap_log`).

use numpy::PyReadonlyArray1;
use pyo3::prelude::*;
use rdm_core::sim::python_float_repr::PythonFloatRepr;

/// ``"v0,v1,..."``: each value as ``repr(float)``, NaN and infinities as ``null`` (the
/// logger's JSON convention); any stride.
#[pyfunction]
fn json_float_list(values: PyReadonlyArray1<'_, f64>) -> String {
    let view = values.as_array();
    // ~24 characters per value at most; one allocation for the result.
    let mut out = String::with_capacity(view.len() * 24);
    let mut writer = PythonFloatRepr::new();
    for (i, v) in view.iter().enumerate() {
        if i > 0 {
            out.push(',');
        }
        writer.push_json(*v, &mut out);
    }
    out
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(json_float_list, m)?)?;
    Ok(())
}
