//! Bindings of `rdm_core::control::lqi` and `rdm_core::control::riccati`.

use nalgebra::{Matrix3, SMatrix, Vector3};
use numpy::ndarray::{Array1, Array2};
use numpy::{
    IntoPyArray, PyArray1, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArrayDyn,
};
use pyo3::create_exception;
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict};

use rdm_core::control::attitude::wire::gains_to_wire;
use rdm_core::control::gains::GainSet;
use rdm_core::control::lqi::{
    self as core_lqi, Allocation, AllocationInverse, GyroCompensation, LqiConfig, LqiError,
    LqiGains, LqiState, LqiWeights, PcAxisController as CorePcAxisController, PcAxisErrors,
    RotorVector,
};
use rdm_core::control::riccati::{
    CareConfig, CareError, CareMethod, CareReport, CareSolver, GainMatrix, InputMatrix,
    InputWeight, StateMatrix, N_STATE,
};
use rdm_core::{check_rotor_count, MAX_ROTORS};

pub(crate) use crate::rotor_arrays::{
    block_to_py, head_to_py, to_rotor_columns, to_rotor_rows, to_rotor_vector,
};

use crate::errors::RdmError;

create_exception!(
    _rdm,
    CareSolveError,
    RdmError,
    "The Riccati solver failed (not stabilisable, not converged, or invalid input)."
);
create_exception!(
    _rdm,
    LqiSynthesisError,
    RdmError,
    "LQI synthesis or the LQI control law failed; the message names the argument."
);

/// Copies a 2-D numpy array of the exact shape into a fixed-size matrix.
pub(crate) fn to_matrix<const R: usize, const C: usize>(
    array: &PyReadonlyArray2<'_, f64>,
    argument: &str,
) -> PyResult<SMatrix<f64, R, C>> {
    let view = array.as_array();
    if view.shape() != [R, C] {
        return Err(RdmError::new_err(format!(
            "`{argument}` must have shape ({R}, {C}), got {:?}",
            view.shape()
        )));
    }
    Ok(SMatrix::from_fn(|i, j| view[[i, j]]))
}

/// Copies a 1-D numpy array of length N.
pub(crate) fn to_vector<const N: usize>(
    array: &PyReadonlyArray1<'_, f64>,
    argument: &str,
) -> PyResult<SMatrix<f64, N, 1>> {
    let view = array.as_array();
    if view.len() != N {
        return Err(RdmError::new_err(format!(
            "`{argument}` must have length {N}, got {}",
            view.len()
        )));
    }
    Ok(SMatrix::from_fn(|i, _| view[i]))
}

/// Fixed-size matrix to a new numpy array.
pub(crate) fn matrix_to_py<'py, const R: usize, const C: usize>(
    py: Python<'py>,
    m: &SMatrix<f64, R, C>,
) -> Bound<'py, PyAny> {
    Array2::from_shape_fn((R, C), |(i, j)| m[(i, j)])
        .into_pyarray(py)
        .into_any()
}

pub(crate) fn vector_to_py<'py, const N: usize>(
    py: Python<'py>,
    v: &SMatrix<f64, N, 1>,
) -> Bound<'py, PyAny> {
    Array1::from_shape_fn(N, |i| v[i])
        .into_pyarray(py)
        .into_any()
}

fn care_error(e: CareError) -> PyErr {
    match e {
        CareError::InvalidInput { argument } => {
            CareSolveError::new_err(format!("invalid argument `{argument}`: {e}"))
        }
        _ => CareSolveError::new_err(e.to_string()),
    }
}

pub(crate) fn lqi_error(e: LqiError) -> PyErr {
    match e {
        LqiError::InvalidInput { argument } => {
            LqiSynthesisError::new_err(format!("invalid argument `{argument}`: {e}"))
        }
        LqiError::Care(inner) => care_error(inner),
        LqiError::SingularAllocation => LqiSynthesisError::new_err(format!("`allocation`: {e}")),
    }
}

fn report_dict<'py>(py: Python<'py>, report: &CareReport) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    let method = match report.method {
        CareMethod::SignFunction => "sign",
        CareMethod::Kleinman => "kleinman",
    };
    d.set_item("method", method)?;
    d.set_item("iterations", report.iterations)?;
    d.set_item("fell_back", report.fell_back)?;
    d.set_item("relative_residual", report.relative_residual)?;
    Ok(d)
}

/// Gain set as a (rotors, 4, 3) array: axes (roll, pitch, yaw, z), columns (P, I, D).
pub(crate) fn gain_set_to_py<'py>(
    py: Python<'py>,
    set: &GainSet,
    rotors: usize,
) -> Bound<'py, PyAny> {
    crate::gains::gain_set_to_array(py, set, rotors).into_any()
}

fn gain_set_from_py(
    array: &PyReadonlyArrayDyn<'_, f64>,
    rotors: Option<usize>,
) -> PyResult<(GainSet, usize)> {
    crate::gains::gain_set_from_view(array.as_array(), rotors)
}

/// Solves the 12-state CARE with m inputs (m in 1..=MAX_ROTORS, the columns of `b`). With `k0`, Kleinman warm start from `k0`
/// (`u = k0 x`) with the cold sign-function method as fallback; otherwise cold.
/// Returns `(P, K, report)` with `K = -R⁻¹BᵀP`.
#[pyfunction]
#[pyo3(signature = (a, b, q, r, k0=None))]
fn solve_care<'py>(
    py: Python<'py>,
    a: PyReadonlyArray2<'py, f64>,
    b: PyReadonlyArray2<'py, f64>,
    q: PyReadonlyArray2<'py, f64>,
    r: PyReadonlyArray2<'py, f64>,
    k0: Option<PyReadonlyArray2<'py, f64>>,
) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>, Bound<'py, PyDict>)> {
    let a: StateMatrix = to_matrix(&a, "a")?;
    let (b, m): (InputMatrix, usize) = to_rotor_columns(&b, "b", None)?;
    let q: StateMatrix = to_matrix(&q, "q")?;
    let r_view = r.as_array();
    if r_view.shape() != [m, m] {
        return Err(RdmError::new_err(format!(
            "`r` must have shape ({m}, {m}) (the columns of `b`), got {:?}",
            r_view.shape()
        )));
    }
    // The inputs past m: unit weight on a zero column of B (they change neither P nor K).
    let r = InputWeight::from_fn(|i, j| match (i < m && j < m, i == j) {
        (true, _) => r_view[[i, j]],
        (false, true) => 1.0,
        (false, false) => 0.0,
    });
    let k0: Option<GainMatrix> = k0
        .map(|k| to_rotor_rows(&k, "k0", Some(m)).map(|(k, _)| k))
        .transpose()?;
    let (result, p, k) = py.detach(move || {
        let mut solver = CareSolver::new(CareConfig::default());
        let result = match k0 {
            Some(k0) => solver.solve_warm_from(&a, &b, &q, &r, &k0),
            None => solver.solve_cold(&a, &b, &q, &r),
        };
        (result, *solver.p(), *solver.k())
    });
    let report = result.map_err(care_error)?;
    Ok((
        matrix_to_py(py, &p),
        block_to_py(py, &k, m, N_STATE),
        report_dict(py, &report)?,
    ))
}

/// `(Ā, B̄)` of eq. (26) in the JSK state order.
#[pyfunction]
fn augmented_system<'py>(
    py: Python<'py>,
    mass: f64,
    inertia: PyReadonlyArray2<'py, f64>,
    allocation: PyReadonlyArray2<'py, f64>,
) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>)> {
    let inertia: Matrix3<f64> = to_matrix(&inertia, "inertia")?;
    let (allocation, n): (Allocation, usize) = to_rotor_columns(&allocation, "allocation", None)?;
    let b = core_lqi::augmented_input_matrix(mass, &inertia, &allocation, n).map_err(lqi_error)?;
    Ok((
        matrix_to_py(py, &core_lqi::augmented_state_matrix()),
        block_to_py(py, &b, N_STATE, n),
    ))
}

/// The sec. 4 mapping of K (rotors x 12) onto the gain set, optionally with `clampGain`.
/// Returns the (rotors, 4, 3) gain array (axes roll, pitch, yaw, z; P, I, D).
#[pyfunction]
#[pyo3(signature = (k, clamp=true))]
fn gain_set_from_k<'py>(
    py: Python<'py>,
    k: PyReadonlyArray2<'py, f64>,
    clamp: bool,
) -> PyResult<Bound<'py, PyAny>> {
    let (k, n): (GainMatrix, usize) = to_rotor_rows(&k, "k", None)?;
    let mut set = core_lqi::gain_set_from_k(&k);
    if clamp {
        core_lqi::clamp_gain(&mut set);
    }
    Ok(gain_set_to_py(py, &set, n))
}

fn gyro_dict<'py>(
    py: Python<'py>,
    gyro: &GyroCompensation,
    rotors: usize,
) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("pinv_roll", head_to_py(py, &gyro.pinv_roll, rotors))?;
    d.set_item("pinv_pitch", head_to_py(py, &gyro.pinv_pitch, rotors))?;
    d.set_item("pinv_yaw", head_to_py(py, &gyro.pinv_yaw, rotors))?;
    d.set_item("inertia", matrix_to_py(py, &gyro.inertia))?;
    let (pseudo, rank) = match gyro.inverse {
        AllocationInverse::Exact => (false, 4),
        AllocationInverse::PseudoInverse { rank } => (true, rank),
    };
    d.set_item("pseudo_inverse", pseudo)?;
    d.set_item("rank", rank)?;
    Ok(d)
}

/// Gyro-compensation data (`p_matrix_pseudo_inverse_inertia` contents, unscaled).
#[pyfunction]
fn gyro_compensation<'py>(
    py: Python<'py>,
    allocation: PyReadonlyArray2<'py, f64>,
    inertia: PyReadonlyArray2<'py, f64>,
) -> PyResult<Bound<'py, PyDict>> {
    let (allocation, n): (Allocation, usize) = to_rotor_columns(&allocation, "allocation", None)?;
    let inertia: Matrix3<f64> = to_matrix(&inertia, "inertia")?;
    let gyro = GyroCompensation::new(&allocation, &inertia, n).map_err(lqi_error)?;
    gyro_dict(py, &gyro, n)
}

/// Eq. (29): `λ_flight = K x̄ + Q̄⁻¹[0; ω×Iω]`; returns (thrust, gyro-compensation dict).
#[pyfunction]
fn flight_thrust<'py>(
    py: Python<'py>,
    k: PyReadonlyArray2<'py, f64>,
    state: PyReadonlyArray1<'py, f64>,
    allocation: PyReadonlyArray2<'py, f64>,
    inertia: PyReadonlyArray2<'py, f64>,
    omega: PyReadonlyArray1<'py, f64>,
) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyDict>)> {
    let (allocation, n): (Allocation, usize) = to_rotor_columns(&allocation, "allocation", None)?;
    let (k, _): (GainMatrix, usize) = to_rotor_rows(&k, "k", Some(n))?;
    let state: LqiState = to_vector::<N_STATE>(&state, "state")?;
    let inertia: Matrix3<f64> = to_matrix(&inertia, "inertia")?;
    let omega: Vector3<f64> = to_vector::<3>(&omega, "omega")?;
    if k.iter().any(|v| !v.is_finite()) {
        return Err(LqiSynthesisError::new_err(
            "invalid argument `k`: not finite",
        ));
    }
    let gyro = GyroCompensation::new(&allocation, &inertia, n).map_err(lqi_error)?;
    let thrust = core_lqi::flight_thrust(&k, &state, &gyro, &omega).map_err(lqi_error)?;
    Ok((head_to_py(py, &thrust, n), gyro_dict(py, &gyro, n)?))
}

/// Stateful LQI gain synthesizer (warm-starts from its previous solution).
#[pyclass(module = "rdm._rdm")]
struct LqiSynthesizer {
    inner: core_lqi::LqiSynthesizer,
    /// The last result `synthesize_wire` accepted (wire terms converted, every gain finite).
    kept: Option<LqiGains>,
    /// What the last `synthesize_wire` returned, handed out again (the same objects,
    /// read-only arrays) while the core answers with that same result (`changes` unchanged).
    last_wire: Option<WireOut>,
}

/// `synthesize_wire`'s tuple, kept.
type WireOut = (
    Py<PyAny>,
    Option<Py<PyAny>>,
    Option<Py<PyBytes>>,
    bool,
    bool,
    bool,
);

/// Marks a numpy array read-only (`a.flags.writeable = False`).
fn read_only(array: &Bound<'_, PyAny>) -> PyResult<()> {
    array.getattr("flags")?.setattr("writeable", false)
}

/// Whether every entry of the gain set is finite.
fn gain_set_finite(set: &GainSet) -> bool {
    set.iter().all(|g| {
        [g.roll, g.pitch, g.yaw, g.z]
            .iter()
            .all(|p| p.p.is_finite() && p.i.is_finite() && p.d.is_finite())
    })
}

fn gains_dict<'py>(py: Python<'py>, g: &LqiGains, rotors: usize) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("k", block_to_py(py, &g.k, rotors, N_STATE))?;
    d.set_item("p", matrix_to_py(py, &g.p))?;
    d.set_item("b", block_to_py(py, &g.b, N_STATE, rotors))?;
    d.set_item("gains", gain_set_to_py(py, &g.gains, rotors))?;
    let s = &g.clamp_scales;
    d.set_item(
        "clamp_scales",
        (s.roll_p, s.roll_d, s.pitch_p, s.pitch_d, s.yaw_d),
    )?;
    d.set_item("report", report_dict(py, &g.report)?)?;
    Ok(d)
}

#[pymethods]
impl LqiSynthesizer {
    /// `rotors`: the rotor count (1..=MAX_ROTORS), fixed for the synthesizer's life; None:
    /// the length of `r_weights`, or 4 (the paper's RDM) without them.
    #[new]
    #[pyo3(signature = (q_weights=None, r_weights=None, clamp_gain=true, kleinman_tolerance=None, rotors=None))]
    fn new(
        q_weights: Option<PyReadonlyArray1<'_, f64>>,
        r_weights: Option<PyReadonlyArray1<'_, f64>>,
        clamp_gain: bool,
        kleinman_tolerance: Option<f64>,
        rotors: Option<usize>,
    ) -> PyResult<Self> {
        let rotors = rotors
            .or_else(|| r_weights.as_ref().map(|w| w.as_array().len()))
            .unwrap_or(4);
        check_rotor_count(rotors)
            .map_err(|e| LqiSynthesisError::new_err(format!("invalid argument `rotors`: {e}")))?;
        let mut config = LqiConfig {
            clamp_gain,
            ..LqiConfig::for_rotors(rotors)
        };
        let defaults = LqiWeights::table_v();
        let q = match q_weights {
            Some(w) => to_vector::<N_STATE>(&w, "q_weights")?.into(),
            None => defaults.q,
        };
        let r = match r_weights {
            Some(w) => to_rotor_vector(&w, "r_weights", rotors)?.into(),
            None => defaults.r,
        };
        config.weights = LqiWeights { q, r };
        if let Some(tolerance) = kleinman_tolerance {
            if !(tolerance.is_finite() && tolerance > 0.0) {
                return Err(LqiSynthesisError::new_err(
                    "invalid argument `kleinman_tolerance`: must be finite and > 0",
                ));
            }
            config.care.kleinman_tolerance = tolerance;
        }
        let inner = core_lqi::LqiSynthesizer::new(config).map_err(lqi_error)?;
        Ok(Self {
            inner,
            kept: None,
            last_wire: None,
        })
    }

    /// The rotor count fixed at construction.
    #[getter]
    fn rotors(&self) -> usize {
        self.inner.config().rotors
    }

    /// Synthesizes gains for (mass, inertia 3x3, allocation 4 x rotors). GIL released.
    fn synthesize<'py>(
        &mut self,
        py: Python<'py>,
        mass: f64,
        inertia: PyReadonlyArray2<'py, f64>,
        allocation: PyReadonlyArray2<'py, f64>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let inertia: Matrix3<f64> = to_matrix(&inertia, "inertia")?;
        let rotors = self.inner.config().rotors;
        let (allocation, _): (Allocation, usize) =
            to_rotor_columns(&allocation, "allocation", Some(rotors))?;
        let changes_before = self.inner.changes();
        let inner = &mut self.inner;
        let result = py.detach(move || inner.synthesize(mass, &inertia, &allocation).copied());
        if result.is_err() || self.inner.changes() != changes_before {
            // solved, another kept solution or failed: the wire objects kept are not its own
            self.last_wire = None;
        }
        gains_dict(py, &result.map_err(lqi_error)?, rotors)
    }

    /// The synthesis of `synthesize` (same solver, same result) in the form the onboard
    /// control tick uses, without the dict of matrices: returns `(gains, wire, payload,
    /// finite, fell_back, clamped)` with `gains` the (rotors, 4, 3) gain array, `wire`
    /// the `rpy/gain` int16 (rotors, 7) terms of `gains_to_wire_terms(gains)` and
    /// `payload` their `spinal/RollPitchYawTerms` bytes (uint32 count, then the int16 terms
    /// little-endian), both None when a term does not convert (NaN/inf); `finite`: every
    /// gain is finite; `fell_back` as in the report; `clamped`: a `clamp_scales` factor is
    /// not 1. A result with `wire` and `finite` is kept (see `kept_result`). Errors as
    /// `synthesize`. GIL released while solving.
    #[allow(clippy::type_complexity)]
    fn synthesize_wire<'py>(
        &mut self,
        py: Python<'py>,
        mass: f64,
        inertia: PyReadonlyArray2<'py, f64>,
        allocation: PyReadonlyArray2<'py, f64>,
    ) -> PyResult<(
        Bound<'py, PyAny>,
        Option<Bound<'py, PyAny>>,
        Option<Bound<'py, PyBytes>>,
        bool,
        bool,
        bool,
    )> {
        let inertia: Matrix3<f64> = to_matrix(&inertia, "inertia")?;
        let rotors = self.inner.config().rotors;
        let (allocation, _): (Allocation, usize) =
            to_rotor_columns(&allocation, "allocation", Some(rotors))?;
        let changes_before = self.inner.changes();
        let inner = &mut self.inner;
        let result = py.detach(move || inner.synthesize(mass, &inertia, &allocation).copied());
        let result = match result {
            Ok(r) => r,
            Err(e) => {
                self.last_wire = None;
                return Err(lqi_error(e));
            }
        };
        if self.inner.changes() == changes_before {
            // the last result again: the objects handed out for it
            if let Some((g, w, b, finite, fell_back, clamped)) = &self.last_wire {
                return Ok((
                    g.bind(py).clone(),
                    w.as_ref().map(|w| w.bind(py).clone()),
                    b.as_ref().map(|b| b.bind(py).clone()),
                    *finite,
                    *fell_back,
                    *clamped,
                ));
            }
        }
        let gains = gain_set_to_py(py, &result.gains, rotors);
        // Handed out again while the solution is reused: read-only, so no caller can change
        // what the next call returns.
        read_only(&gains)?;
        let finite = gain_set_finite(&result.gains);
        let s = &result.clamp_scales;
        let clamped = [s.roll_p, s.roll_d, s.pitch_p, s.pitch_d, s.yaw_d]
            .iter()
            .any(|&v| v != 1.0);
        let fell_back = result.report.fell_back;
        let (wire, payload) = match gains_to_wire(&result.gains) {
            Ok(terms) => {
                let mut flat = [0i16; MAX_ROTORS * 7];
                let mut bytes = [0u8; 4 + MAX_ROTORS * 7 * 2];
                bytes[..4].copy_from_slice(&(rotors as u32).to_le_bytes());
                for (r, term) in terms.iter().enumerate().take(rotors) {
                    for (c, v) in term.to_array().into_iter().enumerate() {
                        let at = r * 7 + c;
                        flat[at] = v;
                        bytes[4 + 2 * at..6 + 2 * at].copy_from_slice(&v.to_le_bytes());
                    }
                }
                let wire = PyArray1::from_slice(py, &flat[..rotors * 7]).reshape([rotors, 7])?;
                read_only(wire.as_any())?;
                (
                    Some(wire.into_any()),
                    Some(PyBytes::new(py, &bytes[..4 + rotors * 7 * 2])),
                )
            }
            Err(_) => (None, None),
        };
        if wire.is_some() && finite {
            self.kept = Some(result);
        }
        self.last_wire = Some((
            gains.clone().unbind(),
            wire.as_ref().map(|w| w.clone().unbind()),
            payload.as_ref().map(|b| b.clone().unbind()),
            finite,
            fell_back,
            clamped,
        ));
        Ok((gains, wire, payload, finite, fell_back, clamped))
    }

    /// The dict `synthesize` returns, for the last result `synthesize_wire` kept (None
    /// before one).
    fn kept_result<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        let rotors = self.inner.config().rotors;
        self.kept
            .as_ref()
            .map(|g| gains_dict(py, g, rotors))
            .transpose()
    }

    /// Forgets the warm start.
    fn reset(&mut self) {
        self.inner.reset();
    }

    /// Calls answered with a kept solution (their B̄ bitwise one of the last
    /// `KEPT_SOLUTIONS` = 4 solved).
    #[getter]
    fn reused(&self) -> u64 {
        self.inner.reused()
    }

    /// Whether a previous solution exists (the next synthesis is warm).
    #[getter]
    fn has_solution(&self) -> bool {
        self.inner.last().is_some()
    }
}

/// PC-side altitude P-I-D (base thrust) and yaw P-I (`angles[2]`) of sec. 4.
#[pyclass(module = "rdm._rdm")]
pub(crate) struct PcAxisController {
    pub(crate) inner: CorePcAxisController,
}

#[pymethods]
impl PcAxisController {
    #[new]
    fn new() -> Self {
        Self {
            inner: CorePcAxisController::new(),
        }
    }

    /// One step for the rotors of `gains` (rotors, 4, 3) and `feed_forward` (rotors,);
    /// returns (base_thrust, yaw_command, yaw_rotor or None).
    #[allow(clippy::too_many_arguments)]
    #[pyo3(signature = (gains, z_error, z_rate_error, yaw_error, feed_forward, dt))]
    fn step<'py>(
        &mut self,
        py: Python<'py>,
        gains: PyReadonlyArrayDyn<'py, f64>,
        z_error: f64,
        z_rate_error: f64,
        yaw_error: f64,
        feed_forward: PyReadonlyArray1<'py, f64>,
        dt: f64,
    ) -> PyResult<(Bound<'py, PyAny>, f64, Option<usize>)> {
        let (gains, n) = gain_set_from_py(&gains, None)?;
        let feed_forward: RotorVector = to_rotor_vector(&feed_forward, "feed_forward", n)?;
        let errors = PcAxisErrors {
            z: z_error,
            z_rate: z_rate_error,
            yaw: yaw_error,
        };
        let command = self
            .inner
            .step(&gains, &errors, &feed_forward, dt)
            .map_err(lqi_error)?;
        Ok((
            head_to_py(py, &command.base_thrust, n),
            command.yaw_command,
            command.yaw_rotor,
        ))
    }

    /// (∫e_z, ∫e_ψ).
    #[getter]
    fn integrals(&self) -> (f64, f64) {
        self.inner.integrals()
    }
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("CareSolveError", py.get_type::<CareSolveError>())?;
    m.add("LqiSynthesisError", py.get_type::<LqiSynthesisError>())?;
    m.add("JSK_TO_PAPER", core_lqi::JSK_TO_PAPER.to_vec())?;
    m.add("MAX_WIRE_GAIN", core_lqi::MAX_WIRE_GAIN)?;
    m.add_function(wrap_pyfunction!(solve_care, m)?)?;
    m.add_function(wrap_pyfunction!(augmented_system, m)?)?;
    m.add_function(wrap_pyfunction!(gain_set_from_k, m)?)?;
    m.add_function(wrap_pyfunction!(gyro_compensation, m)?)?;
    m.add_function(wrap_pyfunction!(flight_thrust, m)?)?;
    m.add_class::<LqiSynthesizer>()?;
    m.add_class::<PcAxisController>()?;
    Ok(())
}
