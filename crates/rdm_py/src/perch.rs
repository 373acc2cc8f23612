//! Bindings of `rdm_core::control::perch`: the perching QP, its controller and the filter.

use nalgebra::{Matrix4, Matrix6x4};
use numpy::{PyArray1, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::create_exception;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use rdm_core::control::perch::{
    PerchController as CoreController, PerchInput, PerchParams, PerchQp as CoreQp, PerchSolution,
    PerchSolver, PerchStatus, WrenchFilter as CoreFilter, N_ROWS, N_VARS, N_ZERO_ROWS,
};
use rdm_core::PERCH_ROTORS;

use crate::errors::RdmError;

create_exception!(
    _rdm,
    PerchError,
    RdmError,
    "Bad argument or parameter of the perching controller (the message names it)."
);

fn err(msg: String) -> PyErr {
    PerchError::new_err(msg)
}

fn vector<const N: usize>(name: &str, a: &PyReadonlyArray1<'_, f64>) -> PyResult<[f64; N]> {
    let view = a.as_array();
    if view.len() != N {
        return Err(err(format!(
            "`{name}` must have {N} entries, got {}",
            view.len()
        )));
    }
    let mut out = [0.0; N];
    for (o, v) in out.iter_mut().zip(view.iter()) {
        *o = *v;
    }
    Ok(out)
}

fn matrix4(name: &str, a: &PyReadonlyArray2<'_, f64>) -> PyResult<Matrix4<f64>> {
    let view = a.as_array();
    if view.shape() != [4, 4] {
        return Err(err(format!("`{name}` must be 4x4, got {:?}", view.shape())));
    }
    Ok(Matrix4::from_fn(|r, c| view[[r, c]]))
}

/// `foot_allocation` as 4 rows (contact-plane coordinates) or 6 rows (foot axes).
enum FootRows {
    Plane(Matrix4<f64>),
    Foot(Matrix6x4<f64>),
}

fn foot_rows(name: &str, a: &PyReadonlyArray2<'_, f64>) -> PyResult<FootRows> {
    let view = a.as_array();
    match view.shape() {
        [4, 4] => Ok(FootRows::Plane(Matrix4::from_fn(|r, c| view[[r, c]]))),
        [6, 4] => Ok(FootRows::Foot(Matrix6x4::from_fn(|r, c| view[[r, c]]))),
        s => Err(err(format!(
            "`{name}` must be 4x4 (plane rows) or 6x4 (foot axes), got {s:?}"
        ))),
    }
}

fn bools<const N: usize>(name: &str, v: Vec<f64>) -> PyResult<[bool; N]> {
    if v.len() != N {
        return Err(err(format!(
            "parameter `{name}` must have {N} entries, got {}",
            v.len()
        )));
    }
    let mut out = [false; N];
    for (o, x) in out.iter_mut().zip(v.iter()) {
        *o = *x != 0.0;
    }
    Ok(out)
}

fn floats<const N: usize>(name: &str, v: Vec<f64>) -> PyResult<[f64; N]> {
    <[f64; N]>::try_from(v.as_slice()).map_err(|_| {
        err(format!(
            "parameter `{name}` must have {N} entries, got {}",
            v.len()
        ))
    })
}

/// Table VII defaults overridden by the entries of `params` (unknown keys are errors).
fn parse_params(params: Option<&Bound<'_, PyDict>>) -> PyResult<PerchParams> {
    let mut p = PerchParams::default();
    let Some(dict) = params else { return Ok(p) };
    for (key, value) in dict.iter() {
        let key: String = key.extract()?;
        let bad = |_| err(format!("parameter `{key}` has the wrong type"));
        match key.as_str() {
            "weight" => p.weight = floats("weight", value.extract().map_err(bad)?)?,
            "wrench_mask" => p.wrench_mask = bools("wrench_mask", value.extract().map_err(bad)?)?,
            "perch_rotors" => {
                p.perch_rotors = bools("perch_rotors", value.extract().map_err(bad)?)?
            }
            "epsilon_z" => p.epsilon_z = value.extract().map_err(bad)?,
            "mu_x" => p.mu_x = value.extract().map_err(bad)?,
            "mu_y" => p.mu_y = value.extract().map_err(bad)?,
            "mu_z" => p.mu_z = value.extract().map_err(bad)?,
            "half_size_x" => p.half_size_x = value.extract().map_err(bad)?,
            "half_size_y" => p.half_size_y = value.extract().map_err(bad)?,
            "zmp_z" => p.zmp_z = value.extract().map_err(bad)?,
            "contact_normal" => {
                p.contact_normal = floats("contact_normal", value.extract().map_err(bad)?)?
            }
            "contact_center" => {
                p.contact_center = floats("contact_center", value.extract().map_err(bad)?)?
            }
            "thrust_rate_limit" => {
                p.thrust_rate_limit = floats("thrust_rate_limit", value.extract().map_err(bad)?)?
            }
            "rotor_thrust_max" => {
                p.rotor_thrust_max = floats("rotor_thrust_max", value.extract().map_err(bad)?)?
            }
            "feedback_gain" => p.feedback_gain = value.extract().map_err(bad)?,
            "gravity" => p.gravity = value.extract().map_err(bad)?,
            "solver" => {
                let name: String = value.extract().map_err(bad)?;
                p.solver = PerchSolver::from_name(&name).ok_or_else(|| {
                    err(format!(
                        "parameter `solver` must be \"active_set\" or \"clarabel\", got {name:?}"
                    ))
                })?
            }
            "active_set_max_iter" => p.active_set_max_iter = value.extract().map_err(bad)?,
            "relax_rate_limit" => p.relax_rate_limit = value.extract().map_err(bad)?,
            "max_iter" => p.max_iter = value.extract().map_err(bad)?,
            "tolerance" => p.tolerance = value.extract().map_err(bad)?,
            _ => return Err(err(format!("unknown perch parameter `{key}`"))),
        }
    }
    Ok(p)
}

fn params_dict<'py>(py: Python<'py>, p: &PerchParams) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("weight", p.weight.to_vec())?;
    d.set_item(
        "wrench_mask",
        p.wrench_mask.map(|b| b as u8 as f64).to_vec(),
    )?;
    d.set_item(
        "perch_rotors",
        p.perch_rotors.map(|b| b as u8 as f64).to_vec(),
    )?;
    d.set_item("epsilon_z", p.epsilon_z)?;
    d.set_item("mu_x", p.mu_x)?;
    d.set_item("mu_y", p.mu_y)?;
    d.set_item("mu_z", p.mu_z)?;
    d.set_item("half_size_x", p.half_size_x)?;
    d.set_item("half_size_y", p.half_size_y)?;
    d.set_item("zmp_z", p.zmp_z)?;
    d.set_item("contact_normal", p.contact_normal.to_vec())?;
    d.set_item("contact_center", p.contact_center.to_vec())?;
    d.set_item("thrust_rate_limit", p.thrust_rate_limit.to_vec())?;
    d.set_item("rotor_thrust_max", p.rotor_thrust_max.to_vec())?;
    d.set_item("feedback_gain", p.feedback_gain)?;
    d.set_item("gravity", p.gravity)?;
    d.set_item("solver", p.solver.as_str())?;
    d.set_item("active_set_max_iter", p.active_set_max_iter)?;
    d.set_item("relax_rate_limit", p.relax_rate_limit)?;
    d.set_item("max_iter", p.max_iter)?;
    d.set_item("tolerance", p.tolerance)?;
    Ok(d)
}

fn solution_dict<'py>(py: Python<'py>, s: &PerchSolution) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("status", s.status.as_str())?;
    d.set_item("thrust", PyArray1::from_slice(py, &s.thrust))?;
    d.set_item("foot_wrench", PyArray1::from_slice(py, &s.foot_wrench))?;
    d.set_item("zmp", PyArray1::from_slice(py, &s.zmp))?;
    d.set_item(
        "friction_margin",
        PyArray1::from_slice(py, &s.friction_margin),
    )?;
    d.set_item("zmp_margin", PyArray1::from_slice(py, &s.zmp_margin))?;
    d.set_item("thrust_min", PyArray1::from_slice(py, &s.thrust_min))?;
    d.set_item("thrust_max", PyArray1::from_slice(py, &s.thrust_max))?;
    d.set_item("iterations", s.iterations)?;
    d.set_item("fallback", s.fallback)?;
    Ok(d)
}

fn counters_dict<'py>(
    py: Python<'py>,
    c: rdm_core::control::perch::PerchCounters,
) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    for status in PerchStatus::ALL {
        d.set_item(status.as_str(), c.count(status))?;
    }
    d.set_item("fallback", c.fallbacks())?;
    Ok(d)
}

fn problem_dict<'py>(py: Python<'py>, qp: &CoreQp) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    let (pc, pr, pv) = qp.p_csc();
    let (ac, ar, av) = qp.a_csc();
    let to_i64 = |v: &[usize]| v.iter().map(|x| *x as i64).collect::<Vec<i64>>();
    d.set_item("n", N_VARS)?;
    d.set_item("m", N_ROWS)?;
    d.set_item("P_colptr", PyArray1::from_vec(py, to_i64(pc)))?;
    d.set_item("P_rowval", PyArray1::from_vec(py, to_i64(pr)))?;
    d.set_item("P_nzval", PyArray1::from_slice(py, pv))?;
    d.set_item("q", PyArray1::from_slice(py, qp.q()))?;
    d.set_item("A_colptr", PyArray1::from_vec(py, to_i64(ac)))?;
    d.set_item("A_rowval", PyArray1::from_vec(py, to_i64(ar)))?;
    d.set_item("A_nzval", PyArray1::from_slice(py, av))?;
    d.set_item("b", PyArray1::from_slice(py, qp.b()))?;
    d.set_item("zero_cone", N_ZERO_ROWS)?;
    d.set_item("nonnegative_cone", N_ROWS - N_ZERO_ROWS)?;
    d.set_item("variable_scale", qp.variable_scale())?;
    Ok(d)
}

fn optional_thrust(
    name: &str,
    a: Option<PyReadonlyArray1<'_, f64>>,
) -> PyResult<Option<[f64; PERCH_ROTORS]>> {
    a.map(|a| vector::<PERCH_ROTORS>(name, &a)).transpose()
}

/// The perching QP of eq. (49) with every input explicit (no filter, no memory).
#[pyclass(module = "rdm._rdm", name = "PerchQp")]
pub struct PyPerchQp {
    inner: CoreQp,
}

#[pymethods]
impl PyPerchQp {
    #[new]
    #[pyo3(signature = (params=None))]
    fn new(params: Option<&Bound<'_, PyDict>>) -> PyResult<Self> {
        let inner = CoreQp::new(parse_params(params)?).map_err(|e| err(e.to_string()))?;
        Ok(Self { inner })
    }

    /// Solve one instance; returns the solution dict (thrust, status, diagnostics). A 4x4
    /// `foot_allocation`: wrench and rows in the contact plane's coordinates; 6x4: foot axes.
    #[allow(clippy::too_many_arguments)]
    #[pyo3(signature = (foot_allocation, allocation, mass, foot_wrench, previous_thrust,
                        previous_foot_wrench, flight_thrust=None))]
    fn solve<'py>(
        &mut self,
        py: Python<'py>,
        foot_allocation: PyReadonlyArray2<'py, f64>,
        allocation: PyReadonlyArray2<'py, f64>,
        mass: f64,
        foot_wrench: PyReadonlyArray1<'py, f64>,
        previous_thrust: PyReadonlyArray1<'py, f64>,
        previous_foot_wrench: PyReadonlyArray1<'py, f64>,
        flight_thrust: Option<PyReadonlyArray1<'py, f64>>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let rows = foot_rows("foot_allocation", &foot_allocation)?;
        let input = PerchInput {
            foot_allocation: match rows {
                FootRows::Plane(m) => m,
                FootRows::Foot(_) => Matrix4::zeros(),
            },
            allocation: matrix4("allocation", &allocation)?,
            mass,
            foot_wrench: vector::<6>("foot_wrench", &foot_wrench)?,
            previous_thrust: vector::<PERCH_ROTORS>("previous_thrust", &previous_thrust)?,
            previous_foot_wrench: vector::<4>("previous_foot_wrench", &previous_foot_wrench)?,
            flight_thrust: optional_thrust("flight_thrust", flight_thrust)?,
        };
        let inner = &mut self.inner;
        let solution = py.detach(|| match rows {
            FootRows::Plane(_) => inner.solve(&input),
            FootRows::Foot(m) => inner.solve_foot(&m, &input),
        });
        solution_dict(py, &solution)
    }

    /// `P, q, A, b` and cone sizes of the last tick's scaled problem (what the active-set
    /// solver reduces and Clarabel is sent).
    fn problem_data<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        problem_dict(py, &self.inner)
    }

    /// Ticks per status.
    fn counters<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        counters_dict(py, self.inner.counters())
    }

    /// Parameters in use.
    fn params<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        params_dict(py, self.inner.params())
    }
}

/// Filter + QP + state: the 40 Hz perching step.
#[pyclass(module = "rdm._rdm", name = "PerchController")]
pub struct PyPerchController {
    inner: CoreController,
}

#[pymethods]
impl PyPerchController {
    #[new]
    #[pyo3(signature = (params=None, rate_hz=40.0, cutoff_hz=1.0))]
    fn new(params: Option<&Bound<'_, PyDict>>, rate_hz: f64, cutoff_hz: f64) -> PyResult<Self> {
        let inner = CoreController::new(parse_params(params)?, rate_hz, cutoff_hz)
            .map_err(|e| err(e.to_string()))?;
        Ok(Self { inner })
    }

    /// One tick from the raw sensor wrench `[F_x, F_y, F_z, M_x, M_y, M_z]`: with a 4x4
    /// `foot_allocation` both are in the contact plane's coordinates (the ceiling: foot
    /// frame), with a 6x4 one both are in foot axes about the foot origin.
    #[pyo3(signature = (foot_wrench, foot_allocation, allocation, mass, flight_thrust=None))]
    fn tick<'py>(
        &mut self,
        py: Python<'py>,
        foot_wrench: PyReadonlyArray1<'py, f64>,
        foot_allocation: PyReadonlyArray2<'py, f64>,
        allocation: PyReadonlyArray2<'py, f64>,
        mass: f64,
        flight_thrust: Option<PyReadonlyArray1<'py, f64>>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let wrench = vector::<6>("foot_wrench", &foot_wrench)?;
        let rows = foot_rows("foot_allocation", &foot_allocation)?;
        let allocation = matrix4("allocation", &allocation)?;
        let flight = optional_thrust("flight_thrust", flight_thrust)?;
        let inner = &mut self.inner;
        let solution = py.detach(|| match rows {
            FootRows::Plane(m) => inner.tick(&wrench, &m, &allocation, mass, flight),
            FootRows::Foot(m) => inner.tick_foot(&wrench, &m, &allocation, mass, flight),
        });
        solution_dict(py, &solution)
    }

    /// Start a perching phase from `thrust` (zeros if omitted); the filter restarts.
    #[pyo3(signature = (thrust=None))]
    fn reset(&mut self, thrust: Option<PyReadonlyArray1<'_, f64>>) -> PyResult<()> {
        let thrust = optional_thrust("thrust", thrust)?.unwrap_or([0.0; PERCH_ROTORS]);
        self.inner.reset(thrust);
        Ok(())
    }

    /// The filtered foot wrench of the last finite sample.
    fn filtered_foot_wrench<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_slice(py, &self.inner.filtered_foot_wrench())
    }

    /// `(b0, b1, a1)` of the foot-wrench filter (scipy `lfilter([b0, b1], [1, a1])`).
    fn filter_coefficients(&self) -> (f64, f64, f64) {
        self.inner.filter().coefficients()
    }

    /// `P, q, A, b` and cone sizes of the last tick's scaled problem (what the active-set
    /// solver reduces and Clarabel is sent).
    fn problem_data<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        problem_dict(py, self.inner.qp())
    }

    /// Ticks per status.
    fn counters<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        counters_dict(py, self.inner.counters())
    }

    /// Parameters in use.
    fn params<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        params_dict(py, self.inner.qp().params())
    }
}

/// The 1 Hz first-order IIR low-pass of Sec. VII-B on 6-component wrenches.
#[pyclass(module = "rdm._rdm", name = "WrenchFilter")]
pub struct PyWrenchFilter {
    inner: CoreFilter,
}

#[pymethods]
impl PyWrenchFilter {
    #[new]
    #[pyo3(signature = (cutoff_hz=1.0, sample_hz=40.0))]
    fn new(cutoff_hz: f64, sample_hz: f64) -> PyResult<Self> {
        let inner = CoreFilter::new(cutoff_hz, sample_hz).ok_or_else(|| {
            err("`cutoff_hz`/`sample_hz`: need 0 < cutoff_hz < sample_hz / 2".to_string())
        })?;
        Ok(Self { inner })
    }

    /// Filter one sample; `None` (state untouched) if it holds NaN/inf.
    fn update<'py>(
        &mut self,
        py: Python<'py>,
        sample: PyReadonlyArray1<'py, f64>,
    ) -> PyResult<Option<Bound<'py, PyArray1<f64>>>> {
        let sample = vector::<6>("sample", &sample)?;
        Ok(self
            .inner
            .update(&sample)
            .map(|y| PyArray1::from_slice(py, &y)))
    }

    /// Forget the history.
    fn reset(&mut self) {
        self.inner.reset();
    }

    /// `(b0, b1, a1)` (scipy `lfilter([b0, b1], [1, a1])`).
    fn coefficients(&self) -> (f64, f64, f64) {
        self.inner.coefficients()
    }
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("PerchError", m.py().get_type::<PerchError>())?;
    m.add("PERCH_ROTORS", PERCH_ROTORS)?;
    m.add_class::<PyPerchQp>()?;
    m.add_class::<PyPerchController>()?;
    m.add_class::<PyWrenchFilter>()?;
    Ok(())
}
