//! The per-rotor gain set as a numpy array of shape (N_ROTORS, 4, 3): rotor, axis (roll,
//! pitch, yaw, z), term (P, I, D). One conversion, shared by every binding that takes or
//! returns gains.

use numpy::ndarray::{Array3, ArrayViewD};
use numpy::{IntoPyArray, PyArray3};
use pyo3::prelude::*;
use rdm_core::control::gains::{GainSet, PidGains};
use rdm_core::N_ROTORS;

use crate::errors::RdmError;

/// A (N_ROTORS, 4, 3) array into a gain set; any other shape is an error naming `gains`.
pub(crate) fn gain_set_from_view(view: ArrayViewD<'_, f64>) -> PyResult<GainSet> {
    if view.shape() != [N_ROTORS, 4, 3] {
        return Err(RdmError::new_err(format!(
            "`gains` must have shape ({N_ROTORS}, 4, 3) (rotor, axis roll/pitch/yaw/z, \
             term P/I/D), got {:?}",
            view.shape()
        )));
    }
    let mut set = GainSet::default();
    for (rotor, g) in set.iter_mut().enumerate() {
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
    Ok(set)
}

/// A gain set into a (N_ROTORS, 4, 3) array.
pub(crate) fn gain_set_to_array<'py>(py: Python<'py>, set: &GainSet) -> Bound<'py, PyArray3<f64>> {
    Array3::from_shape_fn((N_ROTORS, 4, 3), |(rotor, axis, term)| {
        let g = &set[rotor];
        let pid = [g.roll, g.pitch, g.yaw, g.z][axis];
        [pid.p, pid.i, pid.d][term]
    })
    .into_pyarray(py)
}
