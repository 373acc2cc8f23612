//! Bindings of `rdm_core::control::attitude::wire`: gain sets <-> `rpy/gain` int16 x 1000.
//!
//! A gain set in Python is a float array of shape (rotors, 4, 3): rotor, axis (roll,
//! pitch, yaw, z), term (P, I, D). The wire form is an int16 array of shape (rotors, 7):
//! roll_p, roll_i, roll_d, pitch_p, pitch_i, pitch_d, yaw_d.

use numpy::{
    PyArray1, PyArray3, PyArrayMethods, PyReadonlyArray2, PyReadonlyArray3, PyUntypedArrayMethods,
};
use pyo3::prelude::*;
use rdm_core::control::attitude::wire::{
    clamp_gain, gains_from_wire, gains_to_wire, RollPitchYawTermWire,
};
use rdm_core::control::gains::GainSet;
use rdm_core::MAX_ROTORS;

use crate::errors::RdmError;

/// A (rotors, 4, 3) array into a gain set and its rotor count (1..=MAX_ROTORS).
pub(crate) fn gain_set(gains: &PyReadonlyArray3<'_, f64>) -> PyResult<(GainSet, usize)> {
    crate::gains::gain_set_from_view(gains.as_array().into_dyn(), None)
}

/// The first `rotors` entries of a gain set as a (rotors, 4, 3) array.
pub(crate) fn gain_array<'py>(
    py: Python<'py>,
    set: &GainSet,
    rotors: usize,
) -> PyResult<Bound<'py, PyArray3<f64>>> {
    Ok(crate::gains::gain_set_to_array(py, set, rotors))
}

/// Rows of 7 integers (a list of tuples) into wire terms; the same checks and messages as
/// [`wire_terms`].
pub(crate) fn wire_term_rows(rows: &[[i64; 7]]) -> PyResult<Vec<RollPitchYawTermWire>> {
    let mut out = Vec::with_capacity(rows.len());
    for row in rows {
        let mut v = [0i16; 7];
        for (dst, &x) in v.iter_mut().zip(row.iter()) {
            *dst = i16::try_from(x)
                .map_err(|_| RdmError::new_err(format!("terms: {x} is outside int16")))?;
        }
        out.push(RollPitchYawTermWire::from_array(v));
    }
    Ok(out)
}

/// An (n, 7) integer array into wire terms.
pub(crate) fn wire_terms(terms: &PyReadonlyArray2<'_, i64>) -> PyResult<Vec<RollPitchYawTermWire>> {
    if terms.ndim() != 2 || terms.shape()[1] != 7 {
        return Err(RdmError::new_err(
            "terms: need shape (n, 7): roll p/i/d, pitch p/i/d, yaw d",
        ));
    }
    let a = terms.as_array();
    let mut out = Vec::with_capacity(terms.shape()[0]);
    for row in a.rows() {
        let mut v = [0i16; 7];
        for (dst, &x) in v.iter_mut().zip(row.iter()) {
            *dst = i16::try_from(x)
                .map_err(|_| RdmError::new_err(format!("terms: {x} is outside int16")))?;
        }
        out.push(RollPitchYawTermWire::from_array(v));
    }
    Ok(out)
}

/// Gain set (rotors, 4, 3) -> `rpy/gain` int16 (rotors, 7): x1000, truncated toward
/// zero, saturated to int16. Raises on NaN/inf naming the gain.
#[pyfunction]
fn gains_to_wire_terms<'py>(
    py: Python<'py>,
    gains: PyReadonlyArray3<'py, f64>,
) -> PyResult<Bound<'py, numpy::PyArray2<i16>>> {
    let (set, n) = gain_set(&gains)?;
    let wire = gains_to_wire(&set).map_err(|e| RdmError::new_err(format!("gains.{e}")))?;
    let flat: Vec<i16> = wire.iter().take(n).flat_map(|w| w.to_array()).collect();
    PyArray1::from_vec(py, flat).reshape([n, 7])
}

/// `rpy/gain` int16 (rotors, 7) -> the gain set Spinal applies (x 0.001; yaw P/I and z 0).
#[pyfunction]
fn gains_from_wire_terms<'py>(
    py: Python<'py>,
    terms: PyReadonlyArray2<'py, i64>,
) -> PyResult<Bound<'py, PyArray3<f64>>> {
    let terms = wire_terms(&terms)?;
    if !(1..=MAX_ROTORS).contains(&terms.len()) {
        return Err(RdmError::new_err(format!(
            "terms: need 1..={MAX_ROTORS} rows (one per rotor), got {}",
            terms.len()
        )));
    }
    gain_array(py, &gains_from_wire(&terms), terms.len())
}

/// PC-side `clampGain`: returns (scaled gain set, whether anything was scaled).
#[pyfunction(name = "clamp_gain")]
fn py_clamp_gain<'py>(
    py: Python<'py>,
    gains: PyReadonlyArray3<'py, f64>,
) -> PyResult<(Bound<'py, PyArray3<f64>>, bool)> {
    let (mut set, n) = gain_set(&gains)?;
    let scaled = clamp_gain(&mut set);
    Ok((gain_array(py, &set, n)?, scaled))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(gains_to_wire_terms, m)?)?;
    m.add_function(wrap_pyfunction!(gains_from_wire_terms, m)?)?;
    m.add_function(wrap_pyfunction!(py_clamp_gain, m)?)?;
    Ok(())
}
