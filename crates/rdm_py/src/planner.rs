//! Binding of `rdm_core::planner`: `CorePlanner` (one robot, one mode) and
//! `feasible_force`.

use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use numpy::ndarray::Array2;
use numpy::{IntoPyArray, PyReadonlyArray1};
use pyo3::create_exception;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

use rdm_core::model::RobotDescription;
use rdm_core::planner::{
    feasible_force, DamperParams, EeOrientation, Mode, Planner, PlannerConfig, ShapePair,
    ShapeSpec, StepStatus,
};

use crate::errors::{DescriptionError, RdmError};

create_exception!(
    _rdm,
    PlannerError,
    RdmError,
    "Planner setup or input error; the message names the argument or part at fault."
);

fn perr(e: impl std::fmt::Display) -> PyErr {
    PlannerError::new_err(e.to_string())
}

fn damper(d: &Bound<'_, PyDict>, key: &str, out: &mut DamperParams) -> PyResult<()> {
    if let Some(v) = d.get_item(key)? {
        let (r, f, g): (f64, f64, f64) = v.extract().map_err(|_| {
            perr(format!(
                "config['{key}']: expected (restricted, forbidden, gain)"
            ))
        })?;
        *out = DamperParams {
            restricted: r,
            forbidden: f,
            gain: g,
        };
    }
    Ok(())
}

fn parse_config(mode: Mode, d: Option<&Bound<'_, PyDict>>) -> PyResult<PlannerConfig> {
    let mut c = PlannerConfig::new(mode);
    let Some(d) = d else { return Ok(c) };
    macro_rules! f {
        ($key:literal, $field:ident) => {
            if let Some(v) = d.get_item($key)? {
                c.$field = v
                    .extract()
                    .map_err(|_| perr(concat!("config['", $key, "']: expected a number")))?;
            }
        };
    }
    f!("kappa_position", kappa_position);
    f!("kappa_orientation", kappa_orientation);
    f!("s1_position", s1_position);
    f!("s1_orientation", s1_orientation);
    f!("s1_joint", s1_joint);
    f!("s2_ee_position", s2_ee_position);
    f!("s2_ee_orientation", s2_ee_orientation);
    f!("s2_foot", s2_foot);
    f!("step_position", step_position);
    f!("step_angle", step_angle);
    f!("base_tilt_limit", base_tilt_limit);
    f!("ceiling_z", ceiling_z);
    f!("perch_force", perch_force);
    f!("ee_force", ee_force);
    f!("gravity", gravity);
    f!("fd_step", fd_step);
    f!("qp_max_iter", qp_max_iter);
    if let Some(v) = d.get_item("s1_joint_overrides")? {
        c.s1_joint_overrides = v.extract().map_err(|_| {
            perr("config['s1_joint_overrides']: expected a list of (joint index, weight)")
        })?;
    }
    damper(d, "state", &mut c.state)?;
    damper(d, "torque", &mut c.torque)?;
    damper(d, "thrust", &mut c.thrust)?;
    damper(d, "stability", &mut c.stability)?;
    damper(d, "collision", &mut c.collision)?;
    damper(d, "airflow", &mut c.airflow)?;
    if let Some(shapes) = d.get_item("shapes")? {
        for s in shapes
            .cast::<PyList>()
            .map_err(|_| perr("config['shapes']: expected a list"))?
            .iter()
        {
            let (kind, link, a, b, r): (String, usize, [f64; 3], [f64; 3], f64) = s
                .extract()
                .map_err(|_| perr("config['shapes']: expected (kind, link_index, a, b, radius)"))?;
            c.shapes.push(match kind.as_str() {
                "capsule" => ShapeSpec::Capsule {
                    link,
                    a,
                    b,
                    radius: r,
                },
                "sphere" => ShapeSpec::Sphere {
                    link,
                    center: a,
                    radius: r,
                },
                _ => return Err(perr(format!("config['shapes']: unknown kind '{kind}'"))),
            });
        }
    }
    if let Some(pairs) = d.get_item("pairs")? {
        for p in pairs
            .cast::<PyList>()
            .map_err(|_| perr("config['pairs']: expected a list"))?
            .iter()
        {
            let (i, j): (usize, i64) = p
                .extract()
                .map_err(|_| perr("config['pairs']: expected (i, j) or (i, -1)"))?;
            let n = c.shapes.len();
            if i >= n || j >= n as i64 {
                return Err(perr(format!(
                    "config['pairs']: shape index out of range (have {n})"
                )));
            }
            c.pairs.push(if j < 0 {
                ShapePair::Ceiling(i)
            } else {
                ShapePair::Shapes(i, j as usize)
            });
        }
    }
    Ok(c)
}

fn binding_name(b: Option<&'static str>) -> Option<&'static str> {
    b
}

/// The planner core for one robot and mode.
#[pyclass(module = "rdm._rdm", unsendable)]
pub struct CorePlanner {
    inner: Planner,
}

#[pymethods]
impl CorePlanner {
    #[new]
    #[pyo3(signature = (urdf, toml, mode, zeta0, config = None))]
    fn new(
        urdf: &str,
        toml: &str,
        mode: &str,
        zeta0: PyReadonlyArray1<'_, f64>,
        config: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<Self> {
        let robot = RobotDescription::from_strs(urdf, toml, "urdf", "toml")
            .map_err(|e| DescriptionError::new_err(e.to_string()))?;
        let mode = match mode {
            "perched" => Mode::Perched,
            "flight" => Mode::Flight,
            _ => {
                return Err(perr(format!(
                    "mode: expected 'perched' or 'flight', got '{mode}'"
                )))
            }
        };
        let cfg = parse_config(mode, config)?;
        let z = zeta0.as_array().to_vec();
        let inner = Planner::new(robot, cfg, &z).map_err(perr)?;
        Ok(Self { inner })
    }

    /// Current state zeta = [p, eta, q].
    #[getter]
    fn zeta<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        self.inner.zeta().to_vec().into_pyarray(py).into_any()
    }

    fn set_zeta(&mut self, zeta: PyReadonlyArray1<'_, f64>) -> PyResult<()> {
        self.inner.set_zeta(&zeta.as_array().to_vec()).map_err(perr)
    }

    /// zeta indices of the QP variables.
    #[getter]
    fn free(&self) -> Vec<usize> {
        self.inner.free().to_vec()
    }

    /// Quantity vector at the current state.
    #[getter]
    fn values<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        self.inner.values().to_vec().into_pyarray(py).into_any()
    }

    /// Offsets of the quantity vector: dict name -> (start, length).
    #[getter]
    fn layout<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let l = self.inner.layout();
        let d = PyDict::new(py);
        d.set_item("torque", (l.torque(), l.n_q))?;
        d.set_item("thrust", (l.thrust(), l.n_rotors))?;
        d.set_item("thrust_upper", (l.thrust_upper(), l.n_rotors))?;
        d.set_item("rho", (l.rho(), 1))?;
        d.set_item("collision", (l.pairs(), l.n_pairs))?;
        d.set_item("airflow", (l.airflow(), l.airflow_pairs.len()))?;
        d.set_item("airflow_pairs", l.airflow_pairs.clone())?;
        Ok(d)
    }

    /// Recompute and return the quantity Jacobian (len x n_free) at the current state.
    fn linearize<'py>(&mut self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        self.inner.linearize().map_err(perr)?;
        let nf = self.inner.free().len();
        let j = self.inner.jacobian();
        let n = j.len() / nf.max(1);
        Ok(Array2::from_shape_fn((n, nf), |(r, c)| j[r * nf + c])
            .into_pyarray(py)
            .into_any())
    }

    /// End-effector pose: (position[3], quaternion [x, y, z, w]).
    fn end_effector_pose(&self) -> ([f64; 3], [f64; 4]) {
        let p = self.inner.end_effector_pose();
        let t = p.translation.vector;
        let q = p.rotation.coords;
        ([t.x, t.y, t.z], [q.x, q.y, q.z, q.w])
    }

    /// End-effector task rows (eqs. 54, 56) toward `position` with `orientation` or
    /// `axis` at the current state: (rows 6 x n_free over the free state entries, step
    /// delta-xi [6], weights [6]); rows a target leaves free have weight 0.
    #[pyo3(signature = (position, orientation = None, axis = None))]
    #[allow(clippy::type_complexity)]
    fn task_rows<'py>(
        &mut self,
        py: Python<'py>,
        position: [f64; 3],
        orientation: Option<[f64; 4]>,
        axis: Option<[f64; 3]>,
    ) -> PyResult<(Bound<'py, PyAny>, [f64; 6], [f64; 6])> {
        let target = ee_orientation(orientation, axis)?;
        self.inner.task_rows(&position, &target).map_err(perr)?;
        let free = self.inner.free().to_vec();
        let t = self.inner.task();
        let rows = Array2::from_shape_fn((6, free.len()), |(r, c)| t.rows[(r, free[c])]);
        Ok((rows.into_pyarray(py).into_any(), t.step, t.weights))
    }

    /// One step toward `position` and at most one of `orientation` (quaternion
    /// [x, y, z, w]) or `axis` (world direction of the end-effector x axis).
    #[pyo3(signature = (position, orientation = None, axis = None))]
    fn step<'py>(
        &mut self,
        py: Python<'py>,
        position: [f64; 3],
        orientation: Option<[f64; 4]>,
        axis: Option<[f64; 3]>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let target = ee_orientation(orientation, axis)?;
        let inner = &mut self.inner;
        let r = py
            .detach(move || inner.step(&position, &target))
            .map_err(perr)?;
        let d = PyDict::new(py);
        let status = match r.status {
            StepStatus::Moved => "moved".to_owned(),
            StepStatus::QpFailed(s) => format!("qp_failed:{s:?}"),
        };
        d.set_item("status", status)?;
        d.set_item("position_error", r.position_error)?;
        d.set_item("orientation_error", r.orientation_error)?;
        d.set_item("binding", binding_name(r.binding))?;
        Ok(d)
    }

    /// Feasible end-effector force (eq. 3) at the current (perched) state:
    /// (per-axis maxima [3], feasible). None where the thrust allocation is singular.
    fn feasible_force(&self, py: Python<'_>) -> Option<([f64; 3], f64)> {
        let inner = &self.inner;
        py.detach(|| {
            let cfg = inner.config();
            let ws = inner.workspace();
            feasible_force(inner.robot(), ws, cfg.gravity, cfg.perch_force)
                .map(|f| (f.per_axis, f.feasible))
        })
    }
}

/// The orientation part of a target from the binding's optional arguments.
fn ee_orientation(
    orientation: Option<[f64; 4]>,
    axis: Option<[f64; 3]>,
) -> PyResult<EeOrientation> {
    match (orientation, axis) {
        (Some(_), Some(_)) => Err(perr(
            "orientation, axis: give at most one (a full pose or a tool axis)",
        )),
        (Some(o), None) => Ok(EeOrientation::Pose(UnitQuaternion::from_quaternion(
            Quaternion::new(o[3], o[0], o[1], o[2]),
        ))),
        (None, Some(a)) => Ok(EeOrientation::Axis(Vector3::from(a))),
        (None, None) => Ok(EeOrientation::Free),
    }
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<CorePlanner>()?;
    m.add("PlannerError", m.py().get_type::<PlannerError>())?;
    Ok(())
}
