//! Bindings of `rdm_core::estimate`: the Spinal attitude estimator.

use numpy::{PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use rdm_core::estimate::{
    AttitudeEstimate, AttitudeEstimator as CoreEstimator, EstimateStatus, EstimatorConfig,
    EstimatorGuards, ImuSample,
};

use crate::errors::RdmError;

/// Lower-case name of an estimator status, as Python sees it.
pub(crate) fn status_name(status: EstimateStatus) -> &'static str {
    match status {
        EstimateStatus::Ok => "ok",
        EstimateStatus::Calibrating => "calibrating",
        EstimateStatus::AttitudeUndefined => "attitude_undefined",
        EstimateStatus::Degraded => "degraded",
        EstimateStatus::InvalidInput => "invalid_input",
    }
}

/// Keyword overrides of the estimator's guards (an error with `firmware_exact=True`).
const GUARD_KEYS: [&str; 5] = [
    "gyro_range",
    "acc_range",
    "degraded_angle_rad",
    "reinit_angle_rad",
    "reinit_hold_s",
];

/// Builds a checked estimator configuration from a rate, a base (time-matched or not,
/// guarded or firmware-exact) and keyword overrides.
pub(crate) fn estimator_config(
    rate_hz: f64,
    time_matched: bool,
    firmware_exact: bool,
    kwargs: Option<&Bound<'_, PyDict>>,
) -> PyResult<EstimatorConfig> {
    const KNOWN: [&str; 14] = [
        "gyro_calib_duration_s",
        "gyro_lpf_factor",
        "acc_lpf_factor",
        "acc_norm_sq_min",
        "acc_norm_sq_max",
        "acc_prescaler",
        "acc_cmpf_factor",
        "mag_cmpf_factor",
        "mag_outlier_threshold",
        "mag_outlier_max_count",
        "acc_bias",
        "mag_bias",
        "mag_scale",
        "initial_heading",
    ];
    let mut c = if time_matched {
        EstimatorConfig::time_matched(rate_hz)
    } else {
        EstimatorConfig::new(rate_hz)
    };
    if firmware_exact {
        c.guards = None;
    }
    if let Some(kwargs) = kwargs {
        for key in kwargs.keys() {
            let key: String = key.extract()?;
            let guard_key = GUARD_KEYS.contains(&key.as_str());
            if guard_key && firmware_exact {
                return Err(RdmError::new_err(format!(
                    "{key}: a guard parameter, but firmware_exact=True has no guards"
                )));
            }
            if !KNOWN.contains(&key.as_str()) && !guard_key {
                return Err(RdmError::new_err(format!(
                    "{key}: unknown estimator parameter (known: {}, {})",
                    KNOWN.join(", "),
                    GUARD_KEYS.join(", ")
                )));
            }
        }
        let get = |name: &str| -> PyResult<Option<Bound<'_, PyAny>>> { kwargs.get_item(name) };
        macro_rules! set {
            ($target:expr, $field:ident, $ty:ty) => {
                if let Some(v) = get(stringify!($field))? {
                    if !v.is_none() {
                        $target.$field = v.extract::<$ty>().map_err(|e| {
                            RdmError::new_err(format!("{}: {}", stringify!($field), e))
                        })?;
                    }
                }
            };
        }
        set!(c, gyro_calib_duration_s, f64);
        set!(c, gyro_lpf_factor, f64);
        set!(c, acc_lpf_factor, f64);
        set!(c, acc_norm_sq_min, f64);
        set!(c, acc_norm_sq_max, f64);
        set!(c, acc_prescaler, u32);
        set!(c, acc_cmpf_factor, f64);
        set!(c, mag_cmpf_factor, f64);
        set!(c, mag_outlier_threshold, f64);
        set!(c, mag_outlier_max_count, u32);
        set!(c, acc_bias, [f64; 3]);
        set!(c, mag_bias, [f64; 3]);
        set!(c, mag_scale, [f64; 3]);
        set!(c, initial_heading, [f64; 3]);
        if let Some(g) = c.guards.as_mut() {
            set!(g, gyro_range, f64);
            set!(g, acc_range, f64);
            set!(g, degraded_angle_rad, f64);
            set!(g, reinit_angle_rad, f64);
            set!(g, reinit_hold_s, f64);
        }
    }
    c.validate().map_err(|e| RdmError::new_err(e.to_string()))?;
    Ok(c)
}

fn guards_into_dict(g: Option<&EstimatorGuards>, d: &Bound<'_, PyDict>) -> PyResult<()> {
    d.set_item("firmware_exact", g.is_none())?;
    d.set_item("gyro_range", g.map(|g| g.gyro_range))?;
    d.set_item("acc_range", g.map(|g| g.acc_range))?;
    d.set_item("degraded_angle_rad", g.map(|g| g.degraded_angle_rad))?;
    d.set_item("reinit_angle_rad", g.map(|g| g.reinit_angle_rad))?;
    d.set_item("reinit_hold_s", g.map(|g| g.reinit_hold_s))?;
    Ok(())
}

/// The configuration as a dict.
pub(crate) fn config_dict<'py>(
    py: Python<'py>,
    c: &EstimatorConfig,
) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("rate_hz", c.rate_hz)?;
    d.set_item("gyro_calib_duration_s", c.gyro_calib_duration_s)?;
    d.set_item("gyro_lpf_factor", c.gyro_lpf_factor)?;
    d.set_item("acc_lpf_factor", c.acc_lpf_factor)?;
    d.set_item("acc_norm_sq_min", c.acc_norm_sq_min)?;
    d.set_item("acc_norm_sq_max", c.acc_norm_sq_max)?;
    d.set_item("acc_prescaler", c.acc_prescaler)?;
    d.set_item("acc_cmpf_factor", c.acc_cmpf_factor)?;
    d.set_item("mag_cmpf_factor", c.mag_cmpf_factor)?;
    d.set_item("mag_outlier_threshold", c.mag_outlier_threshold)?;
    d.set_item("mag_outlier_max_count", c.mag_outlier_max_count)?;
    d.set_item("acc_bias", c.acc_bias.to_vec())?;
    d.set_item("mag_bias", c.mag_bias.to_vec())?;
    d.set_item("mag_scale", c.mag_scale.to_vec())?;
    d.set_item("initial_heading", c.initial_heading.to_vec())?;
    guards_into_dict(c.guards.as_ref(), &d)?;
    Ok(d)
}

/// 3x3 matrix to numpy (row-major).
pub(crate) fn matrix_to_numpy<'py>(
    py: Python<'py>,
    m: &nalgebra::Matrix3<f64>,
) -> Bound<'py, PyArray2<f64>> {
    let rows: Vec<Vec<f64>> = (0..3)
        .map(|r| (0..3).map(|c| m[(r, c)]).collect())
        .collect();
    PyArray2::from_vec2(py, &rows).expect("3x3 rows have equal length")
}

/// The Spinal complementary-filter attitude estimator (see docs/spinal.md).
///
/// `AttitudeEstimator(rate_hz=200.0, time_matched=False, *, firmware_exact=False,
/// **overrides)`; overrides are the fields of the Rust `EstimatorConfig` (e.g.
/// `gyro_calib_duration_s=3.0`) and of its `EstimatorGuards` (`gyro_range`, `acc_range`,
/// `degraded_angle_rad`, `reinit_angle_rad`, `reinit_hold_s`); `firmware_exact=True` has no
/// guards.
#[pyclass(module = "rdm._rdm", name = "AttitudeEstimator")]
pub struct PyAttitudeEstimator {
    inner: CoreEstimator,
}

pub(crate) fn estimate_into_dict<'py>(
    py: Python<'py>,
    e: &AttitudeEstimate,
    d: &Bound<'py, PyDict>,
) -> PyResult<()> {
    d.set_item("rotation", matrix_to_numpy(py, &e.rotation))?;
    d.set_item("quaternion", PyArray1::from_slice(py, &e.quaternion))?;
    d.set_item("euler", PyArray1::from_slice(py, &e.euler))?;
    d.set_item(
        "angular_velocity",
        PyArray1::from_slice(py, e.angular_velocity.as_slice()),
    )?;
    Ok(())
}

#[pymethods]
impl PyAttitudeEstimator {
    #[new]
    #[pyo3(signature = (rate_hz = 200.0, time_matched = false, *, firmware_exact = false, **overrides))]
    fn new(
        rate_hz: f64,
        time_matched: bool,
        firmware_exact: bool,
        overrides: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<Self> {
        let config = estimator_config(rate_hz, time_matched, firmware_exact, overrides)?;
        let inner = CoreEstimator::new(config).map_err(|e| RdmError::new_err(e.to_string()))?;
        Ok(Self { inner })
    }

    /// One sample (gyro rad/s, acc m/s^2, mag uT; each 3 numbers). Returns the status name.
    fn step(&mut self, gyro: [f64; 3], acc: [f64; 3], mag: [f64; 3]) -> &'static str {
        status_name(self.inner.step(&ImuSample { gyro, acc, mag }))
    }

    /// Runs a whole sequence (arrays of shape (n, 3)); returns a dict of arrays:
    /// rotation (n,3,3), quaternion (n,4) x-y-z-w, euler (n,3), angular_velocity (n,3),
    /// status (list of names).
    fn run<'py>(
        &mut self,
        py: Python<'py>,
        gyro: PyReadonlyArray2<'py, f64>,
        acc: PyReadonlyArray2<'py, f64>,
        mag: PyReadonlyArray2<'py, f64>,
    ) -> PyResult<Bound<'py, PyDict>> {
        for (a, name) in [(&gyro, "gyro"), (&acc, "acc"), (&mag, "mag")] {
            if a.ndim() != 2 || a.shape()[1] != 3 {
                return Err(RdmError::new_err(format!("{name}: need shape (n, 3)")));
            }
        }
        let n = gyro.shape()[0];
        if acc.shape()[0] != n || mag.shape()[0] != n {
            return Err(RdmError::new_err("acc, mag: need the same length as gyro"));
        }
        let g = gyro.as_array().to_owned();
        let a = acc.as_array().to_owned();
        let m = mag.as_array().to_owned();
        let inner = &mut self.inner;
        let (rot, quat, euler, rate, status) = py.detach(move || {
            let mut rot = Vec::with_capacity(n * 9);
            let mut quat = Vec::with_capacity(n * 4);
            let mut euler = Vec::with_capacity(n * 3);
            let mut rate = Vec::with_capacity(n * 3);
            let mut status = Vec::with_capacity(n);
            for k in 0..n {
                let row = |x: &numpy::ndarray::Array2<f64>| [x[[k, 0]], x[[k, 1]], x[[k, 2]]];
                let s = inner.step(&ImuSample {
                    gyro: row(&g),
                    acc: row(&a),
                    mag: row(&m),
                });
                let e = inner.estimate();
                for r in 0..3 {
                    for c in 0..3 {
                        rot.push(e.rotation[(r, c)]);
                    }
                }
                quat.extend_from_slice(&e.quaternion);
                euler.extend_from_slice(&e.euler);
                rate.extend_from_slice(e.angular_velocity.as_slice());
                status.push(status_name(s));
            }
            (rot, quat, euler, rate, status)
        });
        let d = PyDict::new(py);
        d.set_item("rotation", PyArray1::from_vec(py, rot).reshape([n, 3, 3])?)?;
        d.set_item("quaternion", PyArray1::from_vec(py, quat).reshape([n, 4])?)?;
        d.set_item("euler", PyArray1::from_vec(py, euler).reshape([n, 3])?)?;
        d.set_item(
            "angular_velocity",
            PyArray1::from_vec(py, rate).reshape([n, 3])?,
        )?;
        d.set_item("status", status)?;
        Ok(d)
    }

    /// Restarts the gyro bias calibration window.
    fn restart_gyro_calibration(&mut self) {
        self.inner.restart_gyro_calibration();
    }

    /// Body attitude in the world frame (3x3, `v_world = R v_body`).
    #[getter]
    fn rotation<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        matrix_to_numpy(py, &self.inner.estimate().rotation)
    }

    /// Quaternion x, y, z, w (w >= 0).
    #[getter]
    fn quaternion<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_slice(py, &self.inner.estimate().quaternion)
    }

    /// Roll, pitch, yaw (ArduPilot ZYX), rad.
    #[getter]
    fn euler<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_slice(py, &self.inner.estimate().euler)
    }

    /// Filtered, bias-corrected body rate, rad/s.
    #[getter]
    fn angular_velocity<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_slice(py, self.inner.estimate().angular_velocity.as_slice())
    }

    /// Filtered specific force, m/s^2.
    #[getter]
    fn acc<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_slice(py, self.inner.estimate().acc.as_slice())
    }

    /// Magnetometer value after calibration and outlier rejection.
    #[getter]
    fn mag<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_slice(py, self.inner.estimate().mag.as_slice())
    }

    /// The gyro bias in use, rad/s.
    #[getter]
    fn gyro_bias<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_slice(py, self.inner.gyro_bias().as_slice())
    }

    /// Unnormalised gravity and heading filter vectors (body frame), shape (2, 3).
    #[getter]
    fn filter_vectors<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let g = self.inner.gravity_vector();
        let m = self.inner.heading_vector();
        Ok(PyArray2::from_vec2(
            py,
            &[vec![g.x, g.y, g.z], vec![m.x, m.y, m.z]],
        )?)
    }

    /// Counters: steps, invalid_inputs, out_of_range, acc_corrections, mag_corrections,
    /// undefined_attitudes, rescaled_vectors, reinitialisations, degraded_steps.
    #[getter]
    fn counters<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        counters_dict(py, self.inner.counters())
    }

    /// Whether the last step reported "degraded".
    #[getter]
    fn degraded(&self) -> bool {
        self.inner.degraded()
    }

    /// The configuration in use.
    #[getter]
    fn config<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        config_dict(py, self.inner.config())
    }

    /// The latest estimate as a dict of arrays.
    fn estimate<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        estimate_into_dict(py, self.inner.estimate(), &d)?;
        Ok(d)
    }
}

/// The estimator counters as a dict.
pub(crate) fn counters_dict<'py>(
    py: Python<'py>,
    c: &rdm_core::estimate::EstimatorCounters,
) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("steps", c.steps)?;
    d.set_item("invalid_inputs", c.invalid_inputs)?;
    d.set_item("out_of_range", c.out_of_range)?;
    d.set_item("acc_corrections", c.acc_corrections)?;
    d.set_item("mag_corrections", c.mag_corrections)?;
    d.set_item("undefined_attitudes", c.undefined_attitudes)?;
    d.set_item("rescaled_vectors", c.rescaled_vectors)?;
    d.set_item("reinitialisations", c.reinitialisations)?;
    d.set_item("degraded_steps", c.degraded_steps)?;
    Ok(d)
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyAttitudeEstimator>()?;
    Ok(())
}
