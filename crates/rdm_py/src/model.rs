//! Bindings of `rdm_core::model`: the `Robot` class (description + evaluation workspace).

use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};
use numpy::ndarray::{Array1, Array2};
use numpy::IntoPyArray;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};

use rdm_core::model::{
    base_pose_from_zeta, AerialZmp, Frame, Matrix6xN, ModelWorkspace, RobotDescription, StaticLoads,
};

use crate::errors::{DescriptionError, ModelError};

fn model_err(e: rdm_core::model::ModelError) -> PyErr {
    ModelError::new_err(e.to_string())
}

fn vec3_py<'py>(py: Python<'py>, v: &Vector3<f64>) -> Bound<'py, PyAny> {
    Array1::from_vec(vec![v.x, v.y, v.z])
        .into_pyarray(py)
        .into_any()
}

fn mat3_py<'py>(py: Python<'py>, m: &Matrix3<f64>) -> Bound<'py, PyAny> {
    Array2::from_shape_fn((3, 3), |(i, j)| m[(i, j)])
        .into_pyarray(py)
        .into_any()
}

fn pose_py<'py>(py: Python<'py>, p: &Isometry3<f64>) -> Bound<'py, PyAny> {
    let h = p.to_homogeneous();
    Array2::from_shape_fn((4, 4), |(i, j)| h[(i, j)])
        .into_pyarray(py)
        .into_any()
}

fn rows_py<'py>(py: Python<'py>, rows: &[Vector3<f64>]) -> Bound<'py, PyAny> {
    Array2::from_shape_fn((rows.len(), 3), |(i, j)| rows[i][j])
        .into_pyarray(py)
        .into_any()
}

fn matrix_py<'py>(py: Python<'py>, m: &nalgebra::DMatrix<f64>) -> Bound<'py, PyAny> {
    Array2::from_shape_fn((m.nrows(), m.ncols()), |(i, j)| m[(i, j)])
        .into_pyarray(py)
        .into_any()
}

/// `base_pose`: None (identity), a 4x4 homogeneous matrix, or [x, y, z, roll, pitch, yaw].
fn parse_base(base_pose: Option<&Bound<'_, PyAny>>) -> PyResult<Isometry3<f64>> {
    let Some(obj) = base_pose else {
        return Ok(Isometry3::identity());
    };
    if obj.is_none() {
        return Ok(Isometry3::identity());
    }
    if let Ok(rows) = obj.extract::<Vec<Vec<f64>>>() {
        if rows.len() != 4 || rows.iter().any(|r| r.len() != 4) {
            return Err(ModelError::new_err("base_pose: a matrix must be 4x4"));
        }
        if rows.iter().flatten().any(|v| !v.is_finite()) {
            return Err(ModelError::new_err("base_pose: contains NaN or infinity"));
        }
        let r = Matrix3::from_fn(|i, j| rows[i][j]);
        if (r.transpose() * r - Matrix3::identity()).norm() > 1e-6 || r.determinant() < 0.0 {
            return Err(ModelError::new_err(
                "base_pose: the upper-left 3x3 block is not a rotation matrix",
            ));
        }
        let rot = Rotation3::from_matrix(&r);
        let t = Translation3::new(rows[0][3], rows[1][3], rows[2][3]);
        return Ok(Isometry3::from_parts(
            t,
            UnitQuaternion::from_rotation_matrix(&rot),
        ));
    }
    let v: Vec<f64> = obj.extract().map_err(|_| {
        ModelError::new_err("base_pose: expected None, a 4x4 matrix or [x, y, z, roll, pitch, yaw]")
    })?;
    if v.len() != 6 {
        return Err(ModelError::new_err(format!(
            "base_pose: expected 6 values [x, y, z, roll, pitch, yaw], got {}",
            v.len()
        )));
    }
    if v.iter().any(|x| !x.is_finite()) {
        return Err(ModelError::new_err("base_pose: contains NaN or infinity"));
    }
    Ok(base_pose_from_zeta(
        &Vector3::new(v[0], v[1], v[2]),
        &Vector3::new(v[3], v[4], v[5]),
    ))
}

fn wrench6(name: &str, v: Option<Vec<f64>>) -> PyResult<[f64; 6]> {
    match v {
        None => Ok([0.0; 6]),
        Some(v) => <[f64; 6]>::try_from(v.as_slice()).map_err(|_| {
            ModelError::new_err(format!(
                "{name}: expected 6 values [fx, fy, fz, mx, my, mz], got {}",
                v.len()
            ))
        }),
    }
}

fn zmp_dict<'py>(py: Python<'py>, d: &Bound<'py, PyDict>, z: &AerialZmp) -> PyResult<()> {
    d.set_item(
        "aerial_zmp",
        Array1::from_vec(vec![z.point.x, z.point.y]).into_pyarray(py),
    )?;
    d.set_item("zmp_margin", z.margin)?;
    d.set_item("zmp_inside", z.inside)?;
    d.set_item("zmp_degenerate", z.degenerate)?;
    Ok(())
}

/// A robot description with its own evaluation workspace.
#[pyclass(module = "rdm._rdm", subclass)]
pub struct Robot {
    robot: RobotDescription,
    ws: ModelWorkspace,
    urdf_name: String,
    toml_name: String,
}

impl Robot {
    fn build(robot: RobotDescription, urdf_name: String, toml_name: String) -> Self {
        let ws = ModelWorkspace::new(&robot);
        Self {
            robot,
            ws,
            urdf_name,
            toml_name,
        }
    }

    fn eval(&mut self, q: &[f64], base: &Isometry3<f64>) -> PyResult<()> {
        self.robot
            .evaluate(q, base, &mut self.ws)
            .map_err(model_err)
    }
}

#[pymethods]
impl Robot {
    /// Load a robot from a URDF file and a TOML file.
    #[new]
    fn new(urdf: std::path::PathBuf, toml: std::path::PathBuf) -> PyResult<Self> {
        let robot = RobotDescription::from_files(&urdf, &toml)
            .map_err(|e| DescriptionError::new_err(e.to_string()))?;
        Ok(Self::build(
            robot,
            urdf.display().to_string(),
            toml.display().to_string(),
        ))
    }

    /// Build a robot from URDF and TOML text; the names label errors.
    #[staticmethod]
    #[pyo3(signature = (urdf_text, toml_text, urdf_name = "<urdf>", toml_name = "<toml>"))]
    fn from_strs(
        urdf_text: &str,
        toml_text: &str,
        urdf_name: &str,
        toml_name: &str,
    ) -> PyResult<Self> {
        let robot = RobotDescription::from_strs(urdf_text, toml_text, urdf_name, toml_name)
            .map_err(|e| DescriptionError::new_err(e.to_string()))?;
        Ok(Self::build(
            robot,
            urdf_name.to_owned(),
            toml_name.to_owned(),
        ))
    }

    #[getter]
    fn name(&self) -> String {
        self.robot.name.clone()
    }
    #[getter]
    fn sources(&self) -> (String, String) {
        (self.urdf_name.clone(), self.toml_name.clone())
    }
    #[getter]
    fn joint_names(&self) -> Vec<String> {
        self.robot.joint_order.clone()
    }
    #[getter]
    fn n_q(&self) -> usize {
        self.robot.n_q()
    }
    #[getter]
    fn n_rotors(&self) -> usize {
        self.robot.n_rotors()
    }
    #[getter]
    fn mass(&self) -> f64 {
        self.robot.total_mass()
    }
    /// (n_q, 2) array of (lower, upper) position limits [rad].
    #[getter]
    fn joint_limits<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        let l = self.robot.joint_limits();
        Array2::from_shape_fn((l.len(), 2), |(i, j)| if j == 0 { l[i].0 } else { l[i].1 })
            .into_pyarray(py)
            .into_any()
    }
    /// Servo stall torque of each q joint [N m].
    #[getter]
    fn stall_torques<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        Array1::from_vec(self.robot.stall_torque.clone())
            .into_pyarray(py)
            .into_any()
    }
    #[getter]
    fn link_names(&self) -> Vec<String> {
        self.robot.links.iter().map(|l| l.name.clone()).collect()
    }
    #[getter]
    fn rotor_names(&self) -> Vec<String> {
        self.robot.rotors.iter().map(|r| r.name.clone()).collect()
    }
    /// Every frame name `evaluate` reports and `jacobian` accepts.
    #[getter]
    fn frame_names(&self) -> Vec<String> {
        self_frame_names(&self.robot)
    }
    /// Rotor parameters: list of dicts (name, parent, offset, axis, spin, drag_to_thrust,
    /// thrust_min, thrust_max, diameter).
    #[getter]
    fn rotors<'py>(&self, py: Python<'py>) -> PyResult<Vec<Bound<'py, PyDict>>> {
        self.robot
            .rotors
            .iter()
            .map(|r| {
                let d = PyDict::new(py);
                d.set_item("name", &r.name)?;
                d.set_item("parent", &self.robot.links[r.link].name)?;
                d.set_item("offset", vec3_py(py, &r.offset))?;
                d.set_item("axis", vec3_py(py, &r.axis))?;
                d.set_item("spin", r.spin)?;
                d.set_item("drag_to_thrust", r.drag_to_thrust)?;
                d.set_item("thrust_min", r.thrust_min)?;
                d.set_item("thrust_max", r.thrust_max)?;
                d.set_item("diameter", r.diameter)?;
                Ok(d)
            })
            .collect()
    }
    /// Vectoring apparatuses: list of dicts (name, roll_joint, pitch_joint, parent_link, rotors).
    #[getter]
    fn vectoring_units<'py>(&self, py: Python<'py>) -> PyResult<Vec<Bound<'py, PyDict>>> {
        self.robot
            .units
            .iter()
            .map(|u| {
                let d = PyDict::new(py);
                d.set_item("name", &u.name)?;
                d.set_item("roll_joint", &self.robot.joint_order[u.roll_q])?;
                d.set_item("pitch_joint", &self.robot.joint_order[u.pitch_q])?;
                d.set_item("parent_link", &self.robot.links[u.parent_link].name)?;
                let names: Vec<&str> = u
                    .rotors
                    .iter()
                    .map(|&r| self.robot.rotors[r].name.as_str())
                    .collect();
                d.set_item("rotors", names)?;
                Ok(d)
            })
            .collect()
    }
    /// Foot plate size (x, y) [m].
    #[getter]
    fn plate_size(&self) -> (f64, f64) {
        (self.robot.plate_size[0], self.robot.plate_size[1])
    }
    /// Friction placeholders (mu_xy, mu_z).
    #[getter]
    fn friction(&self) -> (f64, f64) {
        (self.robot.friction_xy, self.robot.friction_z)
    }
    /// Wrench sensors: dict name -> dict (frame link, model, force_range, torque_range).
    #[getter]
    fn sensors<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let out = PyDict::new(py);
        for s in &self.robot.sensors {
            let d = PyDict::new(py);
            d.set_item("link", &self.robot.links[s.link].name)?;
            d.set_item("model", &s.model)?;
            d.set_item("force_range", s.force_range.to_vec())?;
            d.set_item("torque_range", s.torque_range.to_vec())?;
            out.set_item(&s.name, d)?;
        }
        Ok(out)
    }

    /// Evaluate at joint vector `q` and `base_pose` (pose of the foot/root link in the world:
    /// None, 4x4, or [x, y, z, roll, pitch, yaw]). Returns a dict of numpy arrays; see the
    /// stub for keys. Positions are world-frame; `inertia` and `allocation` are in the CoG
    /// frame.
    #[pyo3(signature = (q, base_pose = None))]
    fn evaluate<'py>(
        &mut self,
        py: Python<'py>,
        q: Vec<f64>,
        base_pose: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let base = parse_base(base_pose)?;
        self.eval(&q, &base)?;
        let (robot, ws) = (&self.robot, &mut self.ws);
        let d = PyDict::new(py);
        d.set_item("mass", ws.mass)?;
        d.set_item("cog", vec3_py(py, &ws.cog))?;
        d.set_item("inertia", mat3_py(py, &ws.inertia))?;
        d.set_item("inertia_world", mat3_py(py, &ws.inertia_world))?;
        let alloc =
            nalgebra::DMatrix::from_fn(6, ws.allocation.ncols(), |i, j| ws.allocation[(i, j)]);
        d.set_item("allocation", matrix_py(py, &alloc))?;
        d.set_item(
            "allocation_bar",
            matrix_py(py, &alloc.rows(2, 4).into_owned()),
        )?;
        d.set_item("rotor_positions", rows_py(py, &ws.rotor_position))?;
        d.set_item("rotor_directions", rows_py(py, &ws.rotor_direction))?;
        let frames = PyDict::new(py);
        let names = self_frame_names(robot);
        for name in &names {
            let frame = robot.frame(name).map_err(model_err)?;
            frames.set_item(
                name,
                pose_py(py, &robot.frame_pose(ws, frame).map_err(model_err)?),
            )?;
        }
        d.set_item("frames", frames)?;
        d.set_item(
            "foot_in_cog",
            pose_py(py, &robot.foot_in_cog(ws).map_err(model_err)?),
        )?;
        let mut unit_rot = Vec::new();
        for u in 0..robot.units.len() {
            let r = robot.unit_parent_rotation(ws, u).map_err(model_err)?;
            unit_rot.push(mat3_py(py, r.matrix()));
        }
        d.set_item("unit_parent_rotations", unit_rot)?;
        let zmp = robot.aerial_zmp(ws).map_err(model_err)?;
        zmp_dict(py, &d, &zmp)?;
        d.set_item("rho", robot.stability(ws).map_err(model_err)?)?;
        Ok(d)
    }

    /// What the onboard control pipeline reads of `evaluate(q)` (identity base pose), the
    /// same arrays from the same evaluation, without the rest of its dict (every frame's
    /// pose, the ZMP, rho): `(mass, inertia, allocation, allocation_bar, foot_in_cog,
    /// unit_parent_rotations, frames["cog"], frames[frame])`. Errors as `evaluate` (a bad
    /// q), and a ModelError naming an unknown `frame`.
    fn evaluate_control<'py>(
        &mut self,
        py: Python<'py>,
        q: Vec<f64>,
        frame: &str,
    ) -> PyResult<Bound<'py, PyTuple>> {
        let target = self.robot.frame(frame).map_err(model_err)?;
        let cog = self.robot.frame("cog").map_err(model_err)?;
        self.eval(&q, &Isometry3::identity())?;
        let (robot, ws) = (&self.robot, &self.ws);
        let alloc =
            nalgebra::DMatrix::from_fn(6, ws.allocation.ncols(), |i, j| ws.allocation[(i, j)]);
        let mut unit_rot = Vec::with_capacity(robot.units.len());
        for u in 0..robot.units.len() {
            let r = robot.unit_parent_rotation(ws, u).map_err(model_err)?;
            unit_rot.push(mat3_py(py, r.matrix()));
        }
        let items: Vec<Bound<'py, PyAny>> = vec![
            ws.mass.into_pyobject(py)?.into_any(),
            mat3_py(py, &ws.inertia),
            matrix_py(py, &alloc),
            matrix_py(py, &alloc.rows(2, 4).into_owned()),
            pose_py(py, &robot.foot_in_cog(ws).map_err(model_err)?),
            unit_rot.into_pyobject(py)?.into_any(),
            pose_py(py, &robot.frame_pose(ws, cog).map_err(model_err)?),
            pose_py(py, &robot.frame_pose(ws, target).map_err(model_err)?),
        ];
        PyTuple::new(py, items)
    }

    /// Aerial ZMP of eq. (73) for given rotor thrusts; None if no upward thrust.
    #[pyo3(signature = (q, thrusts, base_pose = None))]
    fn aerial_zmp_from_thrusts<'py>(
        &mut self,
        py: Python<'py>,
        q: Vec<f64>,
        thrusts: Vec<f64>,
        base_pose: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Option<Bound<'py, PyDict>>> {
        let base = parse_base(base_pose)?;
        self.eval(&q, &base)?;
        match self
            .robot
            .aerial_zmp_from_thrusts(&mut self.ws, &thrusts)
            .map_err(model_err)?
        {
            None => Ok(None),
            Some(z) => {
                let d = PyDict::new(py);
                zmp_dict(py, &d, &z)?;
                Ok(Some(d))
            }
        }
    }

    /// Static joint torques of eq. (61) (q order) and the net external wrench about the
    /// base origin (zero in equilibrium). Wrenches act on the robot, world axes.
    #[pyo3(signature = (q, thrusts, base_pose = None, foot_wrench = None, end_effector_wrench = None, gravity = (0.0, 0.0, -9.80665)))]
    #[allow(clippy::too_many_arguments)]
    fn static_torques<'py>(
        &mut self,
        py: Python<'py>,
        q: Vec<f64>,
        thrusts: Vec<f64>,
        base_pose: Option<&Bound<'py, PyAny>>,
        foot_wrench: Option<Vec<f64>>,
        end_effector_wrench: Option<Vec<f64>>,
        gravity: (f64, f64, f64),
    ) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>)> {
        let base = parse_base(base_pose)?;
        self.eval(&q, &base)?;
        let foot = wrench6("foot_wrench", foot_wrench)?;
        let ee = wrench6("end_effector_wrench", end_effector_wrench)?;
        let g = [gravity.0, gravity.1, gravity.2];
        let loads = StaticLoads {
            thrusts: &thrusts,
            foot_wrench: &foot,
            end_effector_wrench: &ee,
            gravity: &g,
        };
        let mut tau = vec![0.0; self.robot.n_q()];
        let residual = self
            .robot
            .static_torques(&self.ws, &loads, &mut tau)
            .map_err(model_err)?;
        Ok((
            Array1::from_vec(tau).into_pyarray(py).into_any(),
            Array1::from_vec(residual.as_slice().to_vec())
                .into_pyarray(py)
                .into_any(),
        ))
    }

    /// Jacobian (6 x (6 + n_q)) of `frame` w.r.t. zeta = [p, eta (roll, pitch, yaw), q]:
    /// rows world linear velocity, then world angular velocity.
    fn jacobian<'py>(
        &mut self,
        py: Python<'py>,
        frame: &str,
        zeta: Vec<f64>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let n = 6 + self.robot.n_q();
        if zeta.len() != n {
            return Err(ModelError::new_err(format!(
                "zeta: expected {n} values, got {}",
                zeta.len()
            )));
        }
        let f: Frame = self
            .robot
            .frame(frame)
            .map_err(|e| ModelError::new_err(format!("frame: {e}")))?;
        if zeta[..6].iter().any(|v| !v.is_finite()) {
            return Err(ModelError::new_err(
                "zeta: base entries contain NaN or infinity",
            ));
        }
        let base = base_pose_from_zeta(
            &Vector3::new(zeta[0], zeta[1], zeta[2]),
            &Vector3::new(zeta[3], zeta[4], zeta[5]),
        );
        self.eval(&zeta[6..], &base)?;
        let mut jac = Matrix6xN::zeros(n);
        self.robot
            .frame_jacobian(&self.ws, f, &mut jac)
            .map_err(model_err)?;
        Ok(Array2::from_shape_fn((6, n), |(i, j)| jac[(i, j)])
            .into_pyarray(py)
            .into_any())
    }

    fn __repr__(&self) -> String {
        format!(
            "Robot(name='{}', n_q={}, n_rotors={}, mass={:.3} kg)",
            self.robot.name,
            self.robot.n_q(),
            self.robot.n_rotors(),
            self.robot.total_mass()
        )
    }
}

fn self_frame_names(robot: &RobotDescription) -> Vec<String> {
    let mut names = vec!["world".to_owned(), "cog".to_owned()];
    names.extend(robot.named_frames.iter().map(|(n, _)| n.clone()));
    for n in robot
        .links
        .iter()
        .map(|l| &l.name)
        .chain(robot.rotors.iter().map(|r| &r.name))
    {
        if !names.contains(n) {
            names.push(n.clone());
        }
    }
    names
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Robot>()?;
    Ok(())
}
