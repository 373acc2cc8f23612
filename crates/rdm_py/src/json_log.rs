//! Bindings of `rdm_core::sim::python_float_repr` and `rdm_core::sim::json_text`: JSON text
//! written as Python's `json.dumps` writes it, for the run logger's 100 Hz records
//! (`rdm.sim.mcap_log`, `rdm.sim.json_record`).

use std::fmt::Write;

use numpy::{PyArray1, PyArrayMethods, PyReadonlyArray1};
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyFloat, PyInt, PyList, PyString};
use rdm_core::sim::json_text::{is_plain_key, push_ascii_json_string};
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

/// Append one record value; false when it is outside the fast path (the caller then
/// returns None and Python takes its own path).
fn push_value(v: &Bound<'_, PyAny>, writer: &mut PythonFloatRepr, out: &mut String) -> bool {
    if v.is_none() {
        out.push_str("null");
    } else if v.is_exact_instance_of::<PyBool>() {
        out.push_str(if v.is_truthy().unwrap_or(false) {
            "true"
        } else {
            "false"
        });
    } else if let Ok(f) = v.cast::<PyFloat>() {
        // float and its subclasses (numpy.float64): the stored double, as float.__repr__.
        writer.push_json(f.value(), out);
    } else if v.is_exact_instance_of::<PyInt>() {
        let Ok(i) = v.extract::<i64>() else {
            return false; // beyond i64: Python writes it
        };
        let _ = write!(out, "{i}");
    } else if let Ok(s) = v.cast_exact::<PyString>() {
        let Ok(s) = s.to_str() else {
            return false; // lone surrogates
        };
        push_ascii_json_string(s, out);
    } else if let Ok(a) = v.cast::<PyArray1<f64>>() {
        let Ok(a) = a.try_readonly() else {
            return false;
        };
        out.push('[');
        for (i, x) in a.as_array().iter().enumerate() {
            if i > 0 {
                out.push(',');
            }
            writer.push_json(*x, out);
        }
        out.push(']');
    } else if let Ok(list) = v.cast_exact::<PyList>() {
        out.push('[');
        for (i, x) in list.iter().enumerate() {
            let Ok(x) = x.cast::<PyFloat>() else {
                return false;
            };
            if i > 0 {
                out.push(',');
            }
            writer.push_json(x.value(), out);
        }
        out.push(']');
    } else {
        return false;
    }
    true
}

/// A flat record (a dict of plain str keys to None, bool, float, int, str, 1-D float64
/// arrays, lists of floats) as compact ``json.dumps`` text (NaN and infinities as
/// ``null``); None when the record holds anything else.
#[pyfunction]
fn json_record(values: &Bound<'_, PyAny>) -> Option<String> {
    let dict = values.cast_exact::<PyDict>().ok()?;
    let mut out = String::with_capacity(64 + dict.len() * 64);
    let mut writer = PythonFloatRepr::new();
    out.push('{');
    for (i, (k, v)) in dict.iter().enumerate() {
        let key = k.cast_exact::<PyString>().ok()?.to_str().ok()?;
        if !is_plain_key(key) {
            return None;
        }
        if i > 0 {
            out.push(',');
        }
        out.push('"');
        out.push_str(key);
        out.push_str("\":");
        if !push_value(&v, &mut writer, &mut out) {
            return None;
        }
    }
    out.push('}');
    Some(out)
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(json_float_list, m)?)?;
    m.add_function(wrap_pyfunction!(json_record, m)?)?;
    Ok(())
}
