//! The common case of the onboard node's input check (`rdm.nodes.onboard._vector`) in one
//! call: a list or tuple of exactly `n` Python floats, all finite, as a float64 array. The
//! mocap sample (100 Hz) takes two such checks; in Python they cost ~2.7 us each.

use numpy::PyArray1;
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyFloat, PyList, PyTuple};

/// `value` (a `list` or `tuple`, exactly those types) of `n` exact `float`s: their float64
/// array if all are finite, else False. None when `value` is not of that form (the caller's
/// other paths decide then).
/// `slots` from `len` items, each an exact `float`; None if the count or an item differs.
fn fill<'py>(
    slots: &mut [f64],
    len: usize,
    items: impl Iterator<Item = Bound<'py, PyAny>>,
) -> Option<()> {
    if len != slots.len() {
        return None;
    }
    for (slot, item) in slots.iter_mut().zip(items) {
        *slot = item.cast_exact::<PyFloat>().ok()?.value();
    }
    Some(())
}

#[pyfunction]
fn finite_float_vector<'py>(
    py: Python<'py>,
    value: &Bound<'py, PyAny>,
    n: usize,
) -> Option<Bound<'py, PyAny>> {
    let mut out = [0.0_f64; 16];
    if n > out.len() {
        return None;
    }
    // exactly a list or a tuple (not a subclass) of exactly n exact floats
    let slots = &mut out[..n];
    if let Ok(list) = value.cast_exact::<PyList>() {
        fill(slots, list.len(), list.iter())?;
    } else if let Ok(tuple) = value.cast_exact::<PyTuple>() {
        fill(slots, tuple.len(), tuple.iter())?;
    } else {
        return None;
    }
    if out[..n].iter().all(|v| v.is_finite()) {
        Some(PyArray1::from_slice(py, &out[..n]).into_any())
    } else {
        Some(PyBool::new(py, false).to_owned().into_any())
    }
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(finite_float_vector, m)?)?;
    Ok(())
}
