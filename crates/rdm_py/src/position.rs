//! Bindings of `rdm_core::control::position`.

use nalgebra::{Matrix3, Vector2, Vector3};
use numpy::{PyReadonlyArray1, PyReadonlyArray3};
use pyo3::create_exception;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use rdm_core::control::position::{
    self as core_position, AxisPid, PositionError, PositionGains, PositionInput, Saturation,
    N_VECTORING,
};

use crate::errors::RdmError;
use crate::lqi::{to_vector, vector_to_py};

create_exception!(
    _rdm,
    PositionControlError,
    RdmError,
    "Position control rejected its input; the message names the argument."
);

pub(crate) fn position_error(e: PositionError) -> PyErr {
    match e {
        PositionError::InvalidInput { argument } => {
            PositionControlError::new_err(format!("invalid argument `{argument}`: {e}"))
        }
    }
}

/// Horizontal PID position controller with vectoring angles (eqs. 30-36).
#[pyclass(module = "rdm._rdm")]
pub(crate) struct PositionController {
    pub(crate) inner: core_position::PositionController,
}

#[pymethods]
impl PositionController {
    /// Defaults are Table V (integral limits 1 m/s² and the tilt bound `max_tilt` 1.0 rad
    /// are assumptions).
    #[new]
    #[allow(clippy::too_many_arguments)]
    #[pyo3(signature = (x_pid=None, y_pid=None, integral_limit=None, k_roll=None, k_pitch=None,
                        k_pitch_vectoring=None, k_roll_vectoring=None, gravity=None,
                        max_tilt=None))]
    fn new(
        x_pid: Option<(f64, f64, f64)>,
        y_pid: Option<(f64, f64, f64)>,
        integral_limit: Option<(f64, f64)>,
        k_roll: Option<f64>,
        k_pitch: Option<f64>,
        k_pitch_vectoring: Option<[f64; N_VECTORING]>,
        k_roll_vectoring: Option<[f64; N_VECTORING]>,
        gravity: Option<f64>,
        max_tilt: Option<f64>,
    ) -> PyResult<Self> {
        let mut g = PositionGains::table_v();
        let pid = |t: (f64, f64, f64), limit: f64| AxisPid {
            p: t.0,
            i: t.1,
            d: t.2,
            integral_limit: limit,
        };
        let (limit_x, limit_y) = integral_limit.unwrap_or((g.x.integral_limit, g.y.integral_limit));
        g.x = pid(x_pid.unwrap_or((g.x.p, g.x.i, g.x.d)), limit_x);
        g.y = pid(y_pid.unwrap_or((g.y.p, g.y.i, g.y.d)), limit_y);
        g.k_roll = k_roll.unwrap_or(g.k_roll);
        g.k_pitch = k_pitch.unwrap_or(g.k_pitch);
        g.k_pitch_vectoring = k_pitch_vectoring.unwrap_or(g.k_pitch_vectoring);
        g.k_roll_vectoring = k_roll_vectoring.unwrap_or(g.k_roll_vectoring);
        g.gravity = gravity.unwrap_or(g.gravity);
        g.max_tilt = max_tilt.unwrap_or(g.max_tilt);
        let inner = core_position::PositionController::new(g).map_err(position_error)?;
        Ok(Self { inner })
    }

    /// One step. `link_rotations` has shape (N_VECTORING, 3, 3). Returns a dict with
    /// acceleration, roll, pitch, alpha, beta, direction, integral_clamped, saturated (any
    /// output cut to the tilt bound) and saturation (the cut outputs' names: acceleration,
    /// attitude, vectoring).
    #[allow(clippy::too_many_arguments)]
    fn step<'py>(
        &mut self,
        py: Python<'py>,
        position: PyReadonlyArray1<'py, f64>,
        velocity: PyReadonlyArray1<'py, f64>,
        target_position: PyReadonlyArray1<'py, f64>,
        target_velocity: PyReadonlyArray1<'py, f64>,
        target_yaw: f64,
        link_rotations: PyReadonlyArray3<'py, f64>,
        dt: f64,
    ) -> PyResult<Bound<'py, PyDict>> {
        let rotations_view = link_rotations.as_array();
        if rotations_view.shape() != [N_VECTORING, 3, 3] {
            return Err(RdmError::new_err(format!(
                "`link_rotations` must have shape ({N_VECTORING}, 3, 3), got {:?}",
                rotations_view.shape()
            )));
        }
        let mut rotations = [Matrix3::zeros(); N_VECTORING];
        for (i, r) in rotations.iter_mut().enumerate() {
            *r = Matrix3::from_fn(|a, b| rotations_view[[i, a, b]]);
        }
        let input = PositionInput {
            position: to_vector::<2>(&position, "position")?,
            velocity: to_vector::<2>(&velocity, "velocity")?,
            target_position: to_vector::<2>(&target_position, "target_position")?,
            target_velocity: to_vector::<2>(&target_velocity, "target_velocity")?,
            target_yaw,
            link_rotations: rotations,
            dt,
        };
        let out = self.inner.step(&input).map_err(position_error)?;
        let d = PyDict::new(py);
        d.set_item("acceleration", vector_to_py(py, &out.acceleration))?;
        d.set_item("roll", out.roll)?;
        d.set_item("pitch", out.pitch)?;
        d.set_item("alpha", out.alpha.to_vec())?;
        d.set_item("beta", out.beta.to_vec())?;
        let directions: Vec<Vec<f64>> = out
            .direction
            .iter()
            .map(|n| n.iter().copied().collect())
            .collect();
        d.set_item("direction", directions)?;
        d.set_item("integral_clamped", out.integral_clamped)?;
        d.set_item("saturated", out.saturation.any())?;
        d.set_item("saturation", saturation_names(&out.saturation))?;
        Ok(d)
    }

    /// ∫e dt of x and y.
    #[getter]
    fn integral<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        let v: Vector2<f64> = self.inner.integral();
        vector_to_py(py, &v)
    }

    /// Zeroes the integrators.
    fn reset(&mut self) {
        self.inner.reset();
    }

    /// Bumpless gain switch: takes over ``previous``'s integral action k_I ∫e per axis
    /// (∫e rescaled by k_I,old / k_I,new, clamped to this controller's limit; 0 where the
    /// new k_I is 0).
    fn take_integral_action(&mut self, previous: PyRef<'_, PositionController>) {
        self.inner.take_integral_action(&previous.inner);
    }
}

/// Names of the outputs a step cut to the tilt bound, in a fixed order.
fn saturation_names(s: &Saturation) -> Vec<&'static str> {
    [
        (s.acceleration, "acceleration"),
        (s.attitude, "attitude"),
        (s.vectoring, "vectoring"),
    ]
    .into_iter()
    .filter_map(|(cut, name)| cut.then_some(name))
    .collect()
}

/// Eqs. (33)-(34) for a unit direction n: returns (alpha, beta).
#[pyfunction]
fn vectoring_angles(n: PyReadonlyArray1<'_, f64>) -> PyResult<(f64, f64)> {
    let n: Vector3<f64> = to_vector::<3>(&n, "n")?;
    if n.iter().any(|v| !v.is_finite()) {
        return Err(PositionControlError::new_err(
            "invalid argument `n`: not finite",
        ));
    }
    Ok(core_position::vectoring_angles(&n))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add(
        "PositionControlError",
        py.get_type::<PositionControlError>(),
    )?;
    m.add("N_VECTORING", N_VECTORING)?;
    m.add("GRAVITY", core_position::GRAVITY)?;
    m.add("MAX_TILT_RAD", core_position::MAX_TILT_RAD)?;
    m.add_class::<PositionController>()?;
    m.add_function(wrap_pyfunction!(vectoring_angles, m)?)?;
    Ok(())
}
