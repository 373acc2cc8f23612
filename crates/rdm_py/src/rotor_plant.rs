//! Binding of `rdm_core::sim::rotor_plant`: the plant's per-physics-step rotor work (ESC lag,
//! ceiling distance and ratio, rotor controls) in one call. It holds the MuJoCo buffers it
//! reads and writes (numpy views of one MjData, stable for the data's lifetime) so a step
//! takes no arguments; `rdm.plant.Plant` owns it and the `Esc` objects read and write their
//! thrusts through it.

use numpy::{PyArray1, PyArray2, PyArrayMethods};
use pyo3::exceptions::{PyIndexError, PyValueError};
use pyo3::intern;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};
use rdm_core::sim::esc_duty::EscDuty;
use rdm_core::sim::rotor_plant::{CeilingRatio, RotorPlant, RotorPlantStatus};

use crate::untracked;

/// ESC state, ceiling models and rotor controls of one plant (see `rdm.plant.Plant`).
#[pyclass(module = "rdm._rdm")]
pub(crate) struct RotorPlantCore {
    inner: RotorPlant,
    /// Per rotor: the duty -> thrust map and last duty of its ESC (``Esc`` reads them here).
    escs: Vec<EscDuty>,
    site_xpos: Py<PyArray2<f64>>,
    site_xmat: Py<PyArray2<f64>>,
    ctrl: Py<PyArray1<f64>>,
    /// Where the ground truth reads MjData (see ``set_truth_layout``); None: not set.
    truth: Option<TruthLayout>,
    /// How :meth:`truth_record` builds a record (see ``set_truth_record``); None: not set.
    record: Option<TruthRecord>,
}

/// The record class of :meth:`RotorPlantCore.truth_record` (``rdm.plant.truth.GroundTruth``).
struct TruthRecord {
    /// ``object.__new__``
    new: Py<PyAny>,
    cls: Py<PyAny>,
    /// The class's field names, in field order (``TRUTH_FIELDS`` of them).
    fields: Py<PyTuple>,
    /// The foot plate body (the no-contact measurement's frame).
    plate_body: usize,
}

/// Fields of the ground-truth record, in ``GroundTruth`` field order.
const TRUTH_FIELDS: usize = 18;

/// MjData indices of the 100 Hz ground-truth record (``rdm.plant.Plant._ground_truth``).
#[derive(Clone, Debug)]
struct TruthLayout {
    foot_body: usize,
    ee_body: usize,
    qpos_addresses: Vec<usize>,
    dof_addresses: Vec<usize>,
    fixed_base: bool,
}

/// Row `row` (3 values) of an (n, 3)-shaped C-contiguous view, or an error naming `what`.
fn row3(view: &[f64], row: usize, what: &str) -> PyResult<[f64; 3]> {
    view.get(row * 3..row * 3 + 3)
        .and_then(|r| <[f64; 3]>::try_from(r).ok())
        .ok_or_else(|| PyIndexError::new_err(format!("{what}: body {row} out of range")))
}

/// `view[addresses]` (numpy fancy indexing), or an error naming `what`.
fn gather<'py>(
    py: Python<'py>,
    view: &[f64],
    addresses: &[usize],
    what: &str,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let out = PyArray1::<f64>::zeros(py, addresses.len(), false);
    {
        let mut w = out.try_readwrite()?;
        let w = w.as_slice_mut()?;
        for (dst, &a) in w.iter_mut().zip(addresses) {
            *dst = *view.get(a).ok_or_else(|| {
                PyIndexError::new_err(format!("{what}: address {a} out of range"))
            })?;
        }
    }
    Ok(out)
}

/// A MuJoCo view read for one truth record without borrow tracking (untracked.rs): read
/// only, alive through the allocation of the record's arrays, which writes no view.
fn c_slice<'a>(view: &'a Bound<'_, numpy::PyArrayDyn<f64>>, what: &str) -> PyResult<&'a [f64]> {
    // SAFETY: read only; no Rust code of this crate writes these views meanwhile.
    unsafe { untracked::read(view, what) }
}

fn index_error(what: &str, i: usize) -> PyErr {
    PyIndexError::new_err(format!("{what}: rotor index {i} out of range"))
}

impl RotorPlantCore {
    pub(crate) fn run(&mut self, py: Python<'_>, lag: bool) -> PyResult<()> {
        let (xpos, xmat, ctrl) = (
            self.site_xpos.bind(py),
            self.site_xmat.bind(py),
            self.ctrl.bind(py),
        );
        // SAFETY: ctrl was checked disjoint from the two read arrays at construction, and no
        // Python runs while the slices live (untracked.rs).
        let (xpos, xmat, ctrl) = unsafe {
            (
                untracked::read(xpos, "site_xpos")?,
                untracked::read(xmat, "site_xmat")?,
                untracked::write(ctrl, "ctrl")?,
            )
        };
        let status = if lag {
            self.inner.step(xpos, xmat, ctrl)
        } else {
            self.inner.apply(xpos, xmat, ctrl)
        };
        match status {
            RotorPlantStatus::Ok => Ok(()),
            RotorPlantStatus::SiteOutOfRange => Err(PyValueError::new_err(
                "site_ids: a rotor site id is outside site_xpos/site_xmat",
            )),
            RotorPlantStatus::ActuatorOutOfRange => Err(PyValueError::new_err(
                "actuator_ids: a rotor actuator id is outside ctrl",
            )),
        }
    }
}

#[pymethods]
impl RotorPlantCore {
    /// Rotors stopped, lag factor 0, no ceiling effect; ``ceiling_height`` None: no ceiling.
    #[new]
    #[pyo3(signature = (site_ids, actuator_ids, ceiling_height, site_xpos, site_xmat, ctrl))]
    fn new(
        py: Python<'_>,
        site_ids: Vec<usize>,
        actuator_ids: Vec<usize>,
        ceiling_height: Option<f64>,
        site_xpos: Py<PyArray2<f64>>,
        site_xmat: Py<PyArray2<f64>>,
        ctrl: Py<PyArray1<f64>>,
    ) -> PyResult<Self> {
        if site_ids.len() != actuator_ids.len() {
            return Err(PyValueError::new_err(
                "actuator_ids: must have one entry per site id",
            ));
        }
        let c = ctrl.bind(py);
        let apart = untracked::disjoint(c, site_xpos.bind(py))
            && untracked::disjoint(c, site_xmat.bind(py));
        if !apart {
            return Err(PyValueError::new_err(
                "ctrl: must not share memory with site_xpos or site_xmat",
            ));
        }
        let n = site_ids.len();
        Ok(Self {
            inner: RotorPlant::new(&site_ids, &actuator_ids, ceiling_height),
            escs: vec![EscDuty::new(0.0, 0.0, 0.0, 0.0, 1.0); n],
            site_xpos,
            site_xmat,
            ctrl,
            truth: None,
            record: None,
        })
    }

    /// Number of rotors.
    fn __len__(&self) -> usize {
        self.inner.len()
    }

    /// One physics step: every ESC lag advances, then the ceiling-scaled thrusts go into ctrl.
    fn step(&mut self, py: Python<'_>) -> PyResult<()> {
        self.run(py, true)
    }

    /// The ceiling-scaled present thrusts into ctrl (no lag step).
    fn apply(&mut self, py: Python<'_>) -> PyResult<()> {
        self.run(py, false)
    }

    /// Only the ESC lags advance (a caller that computes the thrusts itself).
    fn advance_lag(&mut self) {
        self.inner.advance_lag();
    }

    /// Present (lagged) thrust of rotor ``i`` [N].
    fn thrust(&self, i: usize) -> PyResult<f64> {
        self.inner.thrust(i).ok_or_else(|| index_error("i", i))
    }

    /// Target thrust of rotor ``i`` [N].
    fn target(&self, i: usize) -> PyResult<f64> {
        self.inner.target(i).ok_or_else(|| index_error("i", i))
    }

    /// Set the present thrust of rotor ``i`` [N].
    fn set_thrust(&mut self, i: usize, value: f64) -> PyResult<()> {
        self.inner
            .set_thrust(i, value)
            .then_some(())
            .ok_or_else(|| index_error("i", i))
    }

    /// Set the target thrust of rotor ``i`` [N].
    fn set_target(&mut self, i: usize, value: f64) -> PyResult<()> {
        self.inner
            .set_target(i, value)
            .then_some(())
            .ok_or_else(|| index_error("i", i))
    }

    /// Set the lag factor ``1 - exp(-dt/tau)`` of rotor ``i``.
    fn set_alpha(&mut self, i: usize, value: f64) -> PyResult<()> {
        self.inner
            .set_alpha(i, value)
            .then_some(())
            .ok_or_else(|| index_error("i", i))
    }

    /// Rotor ``i`` without ceiling effect (T/T0 = 1).
    fn set_ceiling_unity(&mut self, i: usize) -> PyResult<()> {
        self.inner
            .set_ceiling(i, CeilingRatio::Unity)
            .then_some(())
            .ok_or_else(|| index_error("i", i))
    }

    /// Rotor ``i`` with the parametric ceiling effect (the dataclass fields).
    fn set_ceiling_parametric(
        &mut self,
        i: usize,
        radius: f64,
        k1: f64,
        k2_over_radius: f64,
        max_ratio: f64,
    ) -> PyResult<()> {
        let model = CeilingRatio::parametric(radius, k1, k2_over_radius, max_ratio);
        self.inner
            .set_ceiling(i, model)
            .then_some(())
            .ok_or_else(|| index_error("i", i))
    }

    /// Set rotor ``i``'s ESC map (``EscParams`` p2, p1, p0, thrust_max; ``v_factor`` =
    /// ``(v_ref / voltage) ** 2`` computed by Python).
    fn set_esc_map(
        &mut self,
        i: usize,
        p2: f64,
        p1: f64,
        p0: f64,
        thrust_max: f64,
        v_factor: f64,
    ) -> PyResult<()> {
        let e = self.escs.get_mut(i).ok_or_else(|| index_error("i", i))?;
        (e.p2, e.p1, e.p0, e.thrust_max, e.v_factor) = (p2, p1, p0, thrust_max, v_factor);
        Ok(())
    }

    /// Last commanded (clamped) duty of rotor ``i``.
    fn duty(&self, i: usize) -> PyResult<f64> {
        self.escs
            .get(i)
            .map(|e| e.duty)
            .ok_or_else(|| index_error("i", i))
    }

    /// Set rotor ``i``'s last duty (a thrust command's equivalent duty).
    fn set_duty(&mut self, i: usize, value: f64) -> PyResult<()> {
        let e = self.escs.get_mut(i).ok_or_else(|| index_error("i", i))?;
        e.duty = value;
        Ok(())
    }

    /// Non-finite commands rotor ``i`` replaced by a stop.
    fn rejected(&self, i: usize) -> PyResult<u64> {
        self.escs
            .get(i)
            .map(|e| e.rejected)
            .ok_or_else(|| index_error("i", i))
    }

    /// Set rotor ``i``'s rejected-command count.
    fn set_rejected(&mut self, i: usize, value: u64) -> PyResult<()> {
        let e = self.escs.get_mut(i).ok_or_else(|| index_error("i", i))?;
        e.rejected = value;
        Ok(())
    }

    /// Command one duty per rotor (``Esc.command_duty`` of each, in rotor order): clamp,
    /// count non-finite values, new target thrusts. ValueError if the count is wrong
    /// (nothing changes then).
    fn command_duties(&mut self, duties: Vec<f64>) -> PyResult<()> {
        self.kernel_command_duties(&duties)
    }

    /// Thrusts of the last apply/step, ceiling effect included [N].
    fn applied(&self) -> Vec<f64> {
        self.inner.applied().to_vec()
    }

    /// Where :meth:`truth_arrays` reads: the foot and end-effector body ids, the joints'
    /// qpos and dof addresses (joint order), and whether the base is fixed (zero base
    /// velocities).
    fn set_truth_layout(
        &mut self,
        foot_body: usize,
        ee_body: usize,
        qpos_addresses: Vec<usize>,
        dof_addresses: Vec<usize>,
        fixed_base: bool,
    ) {
        self.truth = Some(TruthLayout {
            foot_body,
            ee_body,
            qpos_addresses,
            dof_addresses,
            fixed_base,
        });
    }

    /// The ground truth's MjData copies in one call: (base position, base quaternion, base
    /// linear velocity, base angular velocity, joint positions, joint velocities, CoG,
    /// end-effector position, applied thrusts), each a new float64 array holding the same
    /// values as numpy copies of the MuJoCo data fields (tests/truth_reference.py).
    fn truth_arrays<'py>(
        &self,
        py: Python<'py>,
        xpos: &Bound<'py, numpy::PyArrayDyn<f64>>,
        xquat: &Bound<'py, numpy::PyArrayDyn<f64>>,
        qpos: &Bound<'py, numpy::PyArrayDyn<f64>>,
        qvel: &Bound<'py, numpy::PyArrayDyn<f64>>,
        subtree_com: &Bound<'py, numpy::PyArrayDyn<f64>>,
    ) -> PyResult<Bound<'py, PyTuple>> {
        let layout = self
            .truth
            .as_ref()
            .ok_or_else(|| PyValueError::new_err("set_truth_layout: not called"))?;
        let xpos = c_slice(xpos, "xpos")?;
        let xquat = c_slice(xquat, "xquat")?;
        let qpos = c_slice(qpos, "qpos")?;
        let qvel = c_slice(qvel, "qvel")?;
        let subtree_com = c_slice(subtree_com, "subtree_com")?;
        let fb = layout.foot_body;
        let base_position = row3(xpos, fb, "xpos")?;
        let base_quaternion: [f64; 4] = xquat
            .get(fb * 4..fb * 4 + 4)
            .and_then(|r| <[f64; 4]>::try_from(r).ok())
            .ok_or_else(|| PyIndexError::new_err(format!("xquat: body {fb} out of range")))?;
        let (lin, ang) = if layout.fixed_base {
            ([0.0; 3], [0.0; 3])
        } else {
            let v: [f64; 6] = qvel
                .get(..6)
                .and_then(|r| <[f64; 6]>::try_from(r).ok())
                .ok_or_else(|| PyIndexError::new_err("qvel: fewer than 6 base dofs"))?;
            ([v[0], v[1], v[2]], [v[3], v[4], v[5]])
        };
        let cog = row3(subtree_com, fb, "subtree_com")?;
        let ee_position = row3(xpos, layout.ee_body, "xpos")?;
        let joints = gather(py, qpos, &layout.qpos_addresses, "qpos")?;
        let joint_velocities = gather(py, qvel, &layout.dof_addresses, "qvel")?;
        (
            PyArray1::from_slice(py, &base_position),
            PyArray1::from_slice(py, &base_quaternion),
            PyArray1::from_slice(py, &lin),
            PyArray1::from_slice(py, &ang),
            joints,
            joint_velocities,
            PyArray1::from_slice(py, &cog),
            PyArray1::from_slice(py, &ee_position),
            PyArray1::from_slice(py, self.inner.applied()),
        )
            .into_pyobject(py)
    }

    /// The record :meth:`truth_record` builds: ``new(cls)`` (``object.__new__``) with its
    /// ``__dict__`` filled in ``fields`` order (the 18 ``GroundTruth`` fields), and the foot
    /// plate body whose frame the contact measurement uses.
    fn set_truth_record(
        &mut self,
        py: Python<'_>,
        new: Py<PyAny>,
        cls: Py<PyAny>,
        fields: Py<PyTuple>,
        plate_body: usize,
    ) -> PyResult<()> {
        if fields.bind(py).len() != TRUTH_FIELDS {
            return Err(PyValueError::new_err(format!(
                "fields: expected {TRUTH_FIELDS} names, got {}",
                fields.bind(py).len()
            )));
        }
        self.record = Some(TruthRecord {
            new,
            cls,
            fields,
            plate_body,
        });
        Ok(())
    }

    /// The whole ground-truth record in one call: the :meth:`truth_arrays` values, the
    /// end-effector quaternion as zeros (the caller fills it with ``mju_mat2Quat``) and the
    /// foot contact measurement ``measured`` = ``(points, force, torque, zmp, slip,
    /// slip_yaw)`` of ``FootContactTracker.measure`` (its objects as given; in contact when
    /// ``points > 0``), or None for a plant with no plate contact and no contact anchor (the
    /// flying robot): no contact, force and torque ``-(R.T @ 0)`` (R the plate's frame,
    /// summed in row order: -0.0 for a finite R), ZMP NaN, slip 0, slip yaw 0, the numbers
    /// ``measure`` gives for an empty contact list.
    #[allow(clippy::too_many_arguments)]
    #[pyo3(signature = (time, xpos, xquat, xmat, qpos, qvel, subtree_com, measured=None))]
    fn truth_record<'py>(
        &self,
        py: Python<'py>,
        time: f64,
        xpos: &Bound<'py, numpy::PyArrayDyn<f64>>,
        xquat: &Bound<'py, numpy::PyArrayDyn<f64>>,
        xmat: &Bound<'py, numpy::PyArrayDyn<f64>>,
        qpos: &Bound<'py, numpy::PyArrayDyn<f64>>,
        qvel: &Bound<'py, numpy::PyArrayDyn<f64>>,
        subtree_com: &Bound<'py, numpy::PyArrayDyn<f64>>,
        measured: Option<&Bound<'py, PyTuple>>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let record = self
            .record
            .as_ref()
            .ok_or_else(|| PyValueError::new_err("set_truth_record: not called"))?;
        if let Some(m) = measured {
            if m.len() != 6 {
                return Err(PyValueError::new_err(format!(
                    "measured: expected (points, force, torque, zmp, slip, slip_yaw), got {} values",
                    m.len()
                )));
            }
        }
        let arrays = self.truth_arrays(py, xpos, xquat, qpos, qvel, subtree_com)?;
        let obj = record.new.bind(py).call1((record.cls.bind(py),))?;
        let dict = obj
            .getattr(intern!(py, "__dict__"))?
            .cast_into::<PyDict>()
            .map_err(PyErr::from)?;
        let fields = record.fields.bind(py);
        let f = |i: usize| fields.get_item(i);
        dict.set_item(f(0)?, time)?;
        // base position .. end-effector position (the truth_arrays order, fields 1..=8)
        for i in 0..8 {
            dict.set_item(f(i + 1)?, arrays.get_item(i)?)?;
        }
        dict.set_item(f(9)?, PyArray1::<f64>::zeros(py, 4, false))?;
        dict.set_item(f(10)?, arrays.get_item(8)?)?;
        match measured {
            Some(m) => {
                let points = m.get_item(0)?;
                dict.set_item(f(11)?, points.gt(0)?)?;
                dict.set_item(f(12)?, points)?;
                for i in 1..6 {
                    dict.set_item(f(i + 12)?, m.get_item(i)?)?;
                }
            }
            None => {
                let pb = record.plate_body;
                let plate = c_slice(xmat, "xmat")?
                    .get(pb * 9..pb * 9 + 9)
                    .ok_or_else(|| {
                        PyIndexError::new_err(format!("xmat: body {pb} out of range"))
                    })?;
                // -(R.T @ 0), each component summed over R's rows in order
                let mut zero = [0.0f64; 3];
                for (j, z) in zero.iter_mut().enumerate() {
                    *z = -(plate[j] * 0.0 + plate[3 + j] * 0.0 + plate[6 + j] * 0.0);
                }
                dict.set_item(f(11)?, false)?;
                dict.set_item(f(12)?, 0)?;
                dict.set_item(f(13)?, PyArray1::from_slice(py, &zero))?;
                dict.set_item(f(14)?, PyArray1::from_slice(py, &zero))?;
                dict.set_item(f(15)?, PyArray1::from_slice(py, &[f64::NAN; 2]))?;
                dict.set_item(f(16)?, PyArray1::<f64>::zeros(py, 2, false))?;
                dict.set_item(f(17)?, 0.0)?;
            }
        }
        Ok(obj)
    }

    /// Overwrite the applied thrusts (computed by the caller's own ceiling models).
    fn set_applied(&mut self, values: Vec<f64>) -> PyResult<()> {
        if values.len() != self.inner.len() {
            return Err(PyValueError::new_err(format!(
                "values: expected {} thrusts, got {}",
                self.inner.len(),
                values.len()
            )));
        }
        self.inner.set_applied(&values);
        Ok(())
    }
}

impl RotorPlantCore {
    /// [`RotorPlantCore::command_duties`] on a slice (its one body; the lockstep kernel's
    /// duty hand-over calls it directly).
    pub(crate) fn kernel_command_duties(&mut self, duties: &[f64]) -> PyResult<()> {
        if duties.len() != self.escs.len() {
            return Err(PyValueError::new_err(format!(
                "duties: expected {} values, got {}",
                self.escs.len(),
                duties.len()
            )));
        }
        for (i, (e, d)) in self.escs.iter_mut().zip(duties).enumerate() {
            let target = e.command(*d);
            self.inner.set_target(i, target);
        }
        Ok(())
    }
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<RotorPlantCore>()?;
    Ok(())
}
