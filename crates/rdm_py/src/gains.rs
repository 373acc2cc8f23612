//! The per-rotor gain set as a numpy array of shape (rotors, 4, 3): rotor, axis (roll,
//! pitch, yaw, z), term (P, I, D), with `rotors` in 1..=MAX_ROTORS. One conversion, shared by
//! every binding that takes or returns gains.

use numpy::ndarray::{Array3, ArrayViewD};
use numpy::{IntoPyArray, PyArray3};
use pyo3::prelude::*;
use rdm_core::control::gains::{GainSet, PidGains};
use rdm_core::MAX_ROTORS;

use crate::errors::RdmError;

/// A (rotors, 4, 3) array into a gain set (the rotors past the count zero) and its rotor
/// count; `rotors`: the count the array must have (None: any in 1..=MAX_ROTORS). Any other
/// shape is an error naming `gains`.
pub(crate) fn gain_set_from_view(
    view: ArrayViewD<'_, f64>,
    rotors: Option<usize>,
) -> PyResult<(GainSet, usize)> {
    let shape = view.shape();
    let n = shape.first().copied().unwrap_or(0);
    let count_ok = match rotors {
        Some(r) => n == r,
        None => (1..=MAX_ROTORS).contains(&n),
    };
    if shape.len() != 3 || shape[1..] != [4, 3] || !count_ok {
        let rows = rotors.map_or(format!("1..={MAX_ROTORS}"), |r| r.to_string());
        return Err(RdmError::new_err(format!(
            "`gains` must have shape ({rows}, 4, 3) (rotor, axis roll/pitch/yaw/z, \
             term P/I/D), got {shape:?}"
        )));
    }
    let mut set = GainSet::default();
    for (rotor, g) in set.iter_mut().enumerate().take(n) {
        let pid = |axis: usize| PidGains {
            p: view[[rotor, axis, 0]],
            i: view[[rotor, axis, 1]],
            d: view[[rotor, axis, 2]],
        };
        g.roll = pid(0);
        g.pitch = pid(1);
        g.yaw = pid(2);
        g.z = pid(3);
    }
    Ok((set, n))
}

/// The first `rotors` entries of a gain set as a (rotors, 4, 3) array.
pub(crate) fn gain_set_to_array<'py>(
    py: Python<'py>,
    set: &GainSet,
    rotors: usize,
) -> Bound<'py, PyArray3<f64>> {
    Array3::from_shape_fn((rotors.min(MAX_ROTORS), 4, 3), |(rotor, axis, term)| {
        let g = &set[rotor];
        let pid = [g.roll, g.pitch, g.yaw, g.z][axis];
        [pid.p, pid.i, pid.d][term]
    })
    .into_pyarray(py)
}
