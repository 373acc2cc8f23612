//! Binding of `rdm_core::sim::contact_gate`: the plant's collision gate. It holds the MjData
//! views it reads (stable for the data's lifetime) and the model's `opt`, and keeps the
//! `mjDSBL_CONTACT` bit of `opt.disableflags` in step with its answer, so the plant's Python
//! step and the lockstep kernel share one object and one state (`rdm.plant.contact_gate`).

use numpy::{PyArray1, PyArray2};
use pyo3::exceptions::PyValueError;
use pyo3::intern;
use pyo3::prelude::*;
use rdm_core::sim::contact_gate::{ContactGate, GateReading, MovingGeom, Obstacle, TreeJoint};

use crate::untracked;

/// A plane obstacle: a point and the normal out of the solid.
type PlaneSpec = ([f64; 3], [f64; 3]);
/// A box obstacle: centre, row-major world-from-box rotation, half sizes.
type BoxSpec = ([f64; 3], [f64; 9], [f64; 3]);
/// A moving geom: its row, its bounding radius, the margin per obstacle (None: no pair).
type GeomSpec = (usize, f64, Vec<Option<f64>>);

/// The collision gate of one plant (see ``rdm.plant.contact_gate``).
#[pyclass(module = "rdm._rdm")]
pub(crate) struct ContactGateCore {
    inner: ContactGate,
    root_body: usize,
    /// The `mjDSBL_CONTACT` value of `mujoco.mjtDisableBit`.
    bit: i64,
    opt: Py<PyAny>,
    geom_xpos: Py<PyArray2<f64>>,
    xpos: Py<PyArray2<f64>>,
    xanchor: Py<PyArray2<f64>>,
    qvel: Py<PyArray1<f64>>,
    /// True while the bit is set (contacts off).
    off: bool,
    /// Steps decided with contacts off / on.
    off_steps: u64,
    on_steps: u64,
}

impl ContactGateCore {
    fn reading(&self, py: Python<'_>) -> PyResult<GateReading> {
        let (geom_xpos, xpos, xanchor, qvel) = (
            self.geom_xpos.bind(py),
            self.xpos.bind(py),
            self.xanchor.bind(py),
            self.qvel.bind(py),
        );
        // SAFETY: all four read only, no Python runs while the slices live (untracked.rs).
        let (geom_xpos, xpos, xanchor, qvel) = unsafe {
            (
                untracked::read(geom_xpos, "geom_xpos")?,
                untracked::read(xpos, "xpos")?,
                untracked::read(xanchor, "xanchor")?,
                untracked::read(qvel, "qvel")?,
            )
        };
        let root = xpos
            .get(3 * self.root_body..3 * self.root_body + 3)
            .and_then(|r| <[f64; 3]>::try_from(r).ok())
            .ok_or_else(|| PyValueError::new_err("xpos: the root body is out of range"))?;
        self.inner
            .read(geom_xpos, root, xanchor, qvel)
            .map_err(|e| PyValueError::new_err(e.to_string()))
    }

    fn set_off(&mut self, py: Python<'_>, off: bool) -> PyResult<()> {
        if off == self.off {
            return Ok(());
        }
        let opt = self.opt.bind(py);
        let name = intern!(py, "disableflags");
        let flags: i64 = opt.getattr(name)?.extract()?;
        let flags = if off {
            flags | self.bit
        } else {
            flags & !self.bit
        };
        opt.setattr(name, flags)?;
        self.off = off;
        Ok(())
    }

    /// After a physics step: contacts off for the next pass when none can occur in it, on
    /// otherwise. A state the gate cannot read turns contacts on and raises.
    pub(crate) fn update_now(&mut self, py: Python<'_>) -> PyResult<bool> {
        let possible = match self.reading(py) {
            Ok(r) => r.possible(),
            Err(e) => {
                self.set_off(py, false)?;
                return Err(e);
            }
        };
        self.set_off(py, !possible)?;
        if possible {
            self.on_steps += 1;
        } else {
            self.off_steps += 1;
        }
        Ok(!possible)
    }
}

#[pymethods]
impl ContactGateCore {
    /// ``dt`` the physics step [s], ``slack`` extra reach [m]; ``planes`` and ``boxes`` the
    /// static obstacles (margins in ``geoms`` index planes first, then boxes); ``geoms``
    /// ``(geom, rbound, margins)``; ``free_dof`` the robot's free joint's first dof;
    /// ``hinges`` ``(joint, dof)``, ``slides`` dofs; ``root_body`` the free joint's body;
    /// ``opt`` the model's ``MjOption``, ``bit`` ``mjDSBL_CONTACT``; then the MjData views.
    /// Contacts start on. ValueError on margins that do not match the obstacles.
    #[new]
    #[allow(clippy::too_many_arguments)]
    #[pyo3(signature = (dt, slack, planes, boxes, geoms, free_dof, hinges, slides, root_body,
                        opt, bit, geom_xpos, xpos, xanchor, qvel))]
    fn new(
        dt: f64,
        slack: f64,
        planes: Vec<PlaneSpec>,
        boxes: Vec<BoxSpec>,
        geoms: Vec<GeomSpec>,
        free_dof: usize,
        hinges: Vec<(usize, usize)>,
        slides: Vec<usize>,
        root_body: usize,
        opt: Py<PyAny>,
        bit: i64,
        geom_xpos: Py<PyArray2<f64>>,
        xpos: Py<PyArray2<f64>>,
        xanchor: Py<PyArray2<f64>>,
        qvel: Py<PyArray1<f64>>,
    ) -> PyResult<Self> {
        if !(dt.is_finite() && dt > 0.0 && slack.is_finite() && slack >= 0.0) {
            return Err(PyValueError::new_err(format!(
                "dt must be > 0 and slack >= 0 (finite), got {dt}, {slack}"
            )));
        }
        let n = planes.len() + boxes.len();
        if let Some((g, _, m)) = geoms.iter().find(|(_, _, m)| m.len() != n) {
            return Err(PyValueError::new_err(format!(
                "geom {g}: {} margins for {n} obstacles",
                m.len()
            )));
        }
        let obstacles = planes
            .into_iter()
            .map(|(point, normal)| Obstacle::Plane { point, normal })
            .chain(
                boxes
                    .into_iter()
                    .map(|(center, rot, half)| Obstacle::Box { center, rot, half }),
            )
            .collect();
        let geoms = geoms
            .into_iter()
            .map(|(geom, rbound, margins)| MovingGeom {
                geom,
                rbound,
                margins,
            })
            .collect();
        let joints = hinges
            .into_iter()
            .map(|(joint, dof)| TreeJoint::Hinge { joint, dof })
            .chain(slides.into_iter().map(|dof| TreeJoint::Slide { dof }))
            .collect();
        Ok(Self {
            inner: ContactGate::new(dt, slack, obstacles, geoms, free_dof, joints),
            root_body,
            bit,
            opt,
            geom_xpos,
            xpos,
            xanchor,
            qvel,
            off: false,
            off_steps: 0,
            on_steps: 0,
        })
    }

    /// ``(clearance, reach)`` of the present views [m]: the smallest gap of a colliding pair
    /// (distance - rbound - margin) and how far the tree can move in one step (slack
    /// included). Contact is impossible in the next pass when clearance > reach.
    fn read(&self, py: Python<'_>) -> PyResult<(f64, f64)> {
        let r = self.reading(py)?;
        Ok((r.clearance, r.reach))
    }

    /// Decide for the next pass (call after ``mj_step2``); returns True when contacts are off.
    fn update(&mut self, py: Python<'_>) -> PyResult<bool> {
        self.update_now(py)
    }

    /// Contacts on now (the state may change outside the steps).
    fn enable(&mut self, py: Python<'_>) -> PyResult<()> {
        self.set_off(py, false)
    }

    /// True while contacts are off.
    #[getter]
    fn off(&self) -> bool {
        self.off
    }

    /// Steps after which contacts were off / on.
    #[getter]
    fn off_steps(&self) -> u64 {
        self.off_steps
    }

    #[getter]
    fn on_steps(&self) -> u64 {
        self.on_steps
    }
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<ContactGateCore>()?;
    Ok(())
}
