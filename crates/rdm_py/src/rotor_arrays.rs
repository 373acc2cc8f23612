//! Per-rotor numpy arrays (one row or column per rotor, 1..=MAX_ROTORS of them) to and from
//! the fixed MAX_ROTORS-sized storage of the core: the entries past the rotor count are zero
//! on the way in and left out on the way back.

use nalgebra::SMatrix;
use numpy::ndarray::{Array1, Array2};
use numpy::{IntoPyArray, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;
use rdm_core::{check_rotor_count, MAX_ROTORS};

use crate::errors::RdmError;

/// A (R, n) array, n in 1..=MAX_ROTORS (or exactly `rotors`), into the first n columns of
/// a fixed R x MAX_ROTORS matrix (the rest zero); returns it and n.
pub(crate) fn to_rotor_columns<const R: usize>(
    array: &PyReadonlyArray2<'_, f64>,
    argument: &str,
    rotors: Option<usize>,
) -> PyResult<(SMatrix<f64, R, MAX_ROTORS>, usize)> {
    let view = array.as_array();
    let (rows, n) = (view.shape()[0], view.shape()[1]);
    let count_ok = rotors.map_or(check_rotor_count(n).is_ok(), |r| r == n);
    if rows != R || !count_ok {
        let cols = rotors.map_or(format!("1..={MAX_ROTORS}"), |r| r.to_string());
        return Err(RdmError::new_err(format!(
            "`{argument}` must have shape ({R}, {cols}) (one column per rotor), got {:?}",
            view.shape()
        )));
    }
    Ok((
        SMatrix::from_fn(|i, j| if j < n { view[[i, j]] } else { 0.0 }),
        n,
    ))
}

/// A (n, C) array, n in 1..=MAX_ROTORS (or exactly `rotors`), into the first n rows of a
/// fixed MAX_ROTORS x C matrix (the rest zero); returns it and n.
pub(crate) fn to_rotor_rows<const C: usize>(
    array: &PyReadonlyArray2<'_, f64>,
    argument: &str,
    rotors: Option<usize>,
) -> PyResult<(SMatrix<f64, MAX_ROTORS, C>, usize)> {
    let view = array.as_array();
    let (n, cols) = (view.shape()[0], view.shape()[1]);
    let count_ok = rotors.map_or(check_rotor_count(n).is_ok(), |r| r == n);
    if cols != C || !count_ok {
        let rows = rotors.map_or(format!("1..={MAX_ROTORS}"), |r| r.to_string());
        return Err(RdmError::new_err(format!(
            "`{argument}` must have shape ({rows}, {C}) (one row per rotor), got {:?}",
            view.shape()
        )));
    }
    Ok((
        SMatrix::from_fn(|i, j| if i < n { view[[i, j]] } else { 0.0 }),
        n,
    ))
}

/// A 1-D array of exactly `rotors` entries into a MAX_ROTORS vector (the rest zero).
pub(crate) fn to_rotor_vector(
    array: &PyReadonlyArray1<'_, f64>,
    argument: &str,
    rotors: usize,
) -> PyResult<SMatrix<f64, MAX_ROTORS, 1>> {
    let view = array.as_array();
    if view.len() != rotors {
        return Err(RdmError::new_err(format!(
            "`{argument}` must have length {rotors} (one per rotor), got {}",
            view.len()
        )));
    }
    Ok(SMatrix::from_fn(
        |i, _| if i < rotors { view[i] } else { 0.0 },
    ))
}

/// The first `rows` rows and `cols` columns of a fixed matrix as a new numpy array.
pub(crate) fn block_to_py<'py, const R: usize, const C: usize>(
    py: Python<'py>,
    m: &SMatrix<f64, R, C>,
    rows: usize,
    cols: usize,
) -> Bound<'py, PyAny> {
    Array2::from_shape_fn((rows.min(R), cols.min(C)), |(i, j)| m[(i, j)])
        .into_pyarray(py)
        .into_any()
}

/// The first `n` entries of a fixed vector as a new numpy array.
pub(crate) fn head_to_py<'py, const N: usize>(
    py: Python<'py>,
    v: &SMatrix<f64, N, 1>,
    n: usize,
) -> Bound<'py, PyAny> {
    Array1::from_shape_fn(n.min(N), |i| v[i])
        .into_pyarray(py)
        .into_any()
}
