//! The plant side of the kernel: `rdm.plant.Plant`'s lazy forward pass and its one-step
//! physics (`Plant.sync`, `Plant.step(1)`), with the plant's flags kept here between Python
//! calls and written back before any Python code runs; the sleep-at-rest rule is the plant's
//! own `RestingSleepCore`.

use numpy::PyArrayMethods;
use pyo3::prelude::*;

use super::attr::Name;
use super::option_flags::OptionFlags;
use crate::contact_gate::ContactGateCore;
use crate::resting_sleep::RestingSleepCore;
use crate::rotor_plant::RotorPlantCore;
use crate::untracked;

struct Names {
    stale: Name,
    needs_step1: Name,
    state_version: Name,
    rotors_in_core: Name,
    external: Name,
    anchor_pos: Name,
    last_contact_time: Name,
    ncon: Name,
    update: Name,
    time: Name,
    rejected_commands: Name,
    sensor_bit: Name,
}

/// What `LockstepKernel.attach_plant` is given of an `rdm.plant.Plant` at construction
/// (typed; the caller reads them, the kernel holds them for the plant's lifetime).
pub(crate) struct PlantParts {
    /// `MjModel`, `MjData`.
    pub(crate) model: Py<PyAny>,
    pub(crate) data: Py<PyAny>,
    /// `mujoco.mj_step1`, `mj_step2`, `mj_forward`, `mj_sensorPos`, `mj_sensorVel`.
    pub(crate) mj: [Py<PyAny>; 5],
    /// `Plant._flags_address`, `model._address` (None: unknown) and
    /// `rdm.plant.option_flags.SEARCH_BYTES`.
    pub(crate) flags_address: Option<usize>,
    pub(crate) model_address: Option<usize>,
    pub(crate) search_bytes: usize,
    /// `model.opt`.
    pub(crate) opt: Py<PyAny>,
    pub(crate) rotors: Py<RotorPlantCore>,
    pub(crate) gate: Option<Py<ContactGateCore>>,
    /// `Plant._tracker` (the foot contact tracker).
    pub(crate) tracker: Py<PyAny>,
    pub(crate) qpos: Py<numpy::PyArray1<f64>>,
    pub(crate) sensordata: Py<numpy::PyArray1<f64>>,
    pub(crate) ctrl: Py<numpy::PyArray1<f64>>,
    pub(crate) servo_act: Vec<usize>,
    /// `Plant.sleep`'s core (the robot's sleep at rest), when the plant has it.
    pub(crate) sleep: Option<Py<RestingSleepCore>>,
}

/// One MuJoCo plant as the kernel drives it.
pub(crate) struct PlantLink {
    plant: Py<PyAny>,
    model: Py<PyAny>,
    data: Py<PyAny>,
    step1: Py<PyAny>,
    step2: Py<PyAny>,
    forward: Py<PyAny>,
    sensor_pos: Py<PyAny>,
    sensor_vel: Py<PyAny>,
    /// `model.opt.disableflags`, which get `Plant._sensor_bit` while a step runs.
    flags: OptionFlags,
    rotors: Py<RotorPlantCore>,
    /// `Plant._contact_gate` (None: contacts always on).
    gate: Option<Py<ContactGateCore>>,
    tracker: Py<PyAny>,
    /// Plant's `_v_qpos`, `_v_sensordata`, `_v_ctrl` (views of MjData, stable for its life).
    pub(crate) qpos: Py<numpy::PyArray1<f64>>,
    pub(crate) sensordata: Py<numpy::PyArray1<f64>>,
    pub(crate) ctrl: Py<numpy::PyArray1<f64>>,
    /// Servo actuator index per joint (`Plant._servo_act`).
    servo_act: Vec<usize>,
    /// `Plant.sleep`'s core (the robot's sleep at rest), when the plant has it.
    sleep: Option<Py<RestingSleepCore>>,
    names: Names,
    // ---- plan (read by `load`, written back by `flush`)
    loaded: bool,
    dirty: bool,
    stale: bool,
    needs_step1: bool,
    version: i64,
    /// `Plant._sensor_bit` (0: sensors in every step).
    sensor_bit: i64,
    /// `Plant.step` can run here: rotors in the Rust core, no held external wrench.
    step_ok: bool,
    /// The contact tracker has no contact to remember or release (`update` returns at once
    /// while there is no contact).
    tracker_idle: bool,
    /// `FootContactTracker.kernel_plan`: the cached contact view (its ncon, the geom pairs),
    /// the plate's geoms, whether the first-contact anchor is set.
    tracker_view: Option<(i64, Py<numpy::PyArray2<i32>>)>,
    plate_geoms: Vec<i32>,
    anchored: bool,
    /// Tracker updates run here / in Python (diagnostics).
    pub(crate) tracker_fast: u64,
    pub(crate) tracker_python: u64,
}

impl PlantLink {
    pub(crate) fn new(py: Python<'_>, plant: &Bound<'_, PyAny>, parts: PlantParts) -> Self {
        let [step1, step2, forward, sensor_pos, sensor_vel] = parts.mj;
        PlantLink {
            plant: plant.clone().unbind(),
            model: parts.model,
            data: parts.data,
            step1,
            step2,
            forward,
            sensor_pos,
            sensor_vel,
            flags: OptionFlags::new(
                py,
                parts.flags_address,
                parts.model_address,
                parts.search_bytes,
                parts.opt,
            ),
            rotors: parts.rotors,
            gate: parts.gate,
            tracker: parts.tracker,
            qpos: parts.qpos,
            sensordata: parts.sensordata,
            ctrl: parts.ctrl,
            servo_act: parts.servo_act,
            sleep: parts.sleep,
            names: Names {
                stale: Name::new(py, "_stale"),
                needs_step1: Name::new(py, "_needs_step1"),
                state_version: Name::new(py, "_state_version"),
                rotors_in_core: Name::new(py, "_rotors_in_core"),
                external: Name::new(py, "_external"),
                anchor_pos: Name::new(py, "_anchor_pos"),
                last_contact_time: Name::new(py, "_last_contact_time"),
                ncon: Name::new(py, "ncon"),
                update: Name::new(py, "update"),
                time: Name::new(py, "time"),
                rejected_commands: Name::new(py, "rejected_commands"),
                sensor_bit: Name::new(py, "_sensor_bit"),
            },
            loaded: false,
            dirty: false,
            stale: true,
            needs_step1: true,
            version: 0,
            sensor_bit: 0,
            step_ok: false,
            tracker_idle: false,
            tracker_view: None,
            plate_geoms: Vec::new(),
            anchored: false,
            tracker_fast: 0,
            tracker_python: 0,
        }
    }

    /// Forget the plan: Python code may have run.
    pub(crate) fn invalidate(&mut self) {
        self.loaded = false;
    }

    fn ensure_loaded(&mut self, py: Python<'_>) -> PyResult<()> {
        if self.loaded {
            return Ok(());
        }
        let p = self.plant.bind(py);
        let n = &self.names;
        self.stale = n.stale.truthy(p)?;
        self.needs_step1 = n.needs_step1.truthy(p)?;
        self.version = n.state_version.i64(p)?;
        self.sensor_bit = n.sensor_bit.i64(p)?;
        let external_empty = n.external.get(p)?.len()? == 0;
        self.step_ok = n.rotors_in_core.truthy(p)? && external_empty;
        self.load_tracker(py)?;
        self.loaded = true;
        Ok(())
    }

    fn load_tracker(&mut self, py: Python<'_>) -> PyResult<()> {
        let tr = self.tracker.bind(py);
        let n = &self.names;
        self.tracker_idle =
            n.anchor_pos.is_none(tr)? && n.last_contact_time.f64(tr)? == f64::NEG_INFINITY;
        let plan = tr.call_method1("kernel_plan", (self.data.bind(py),))?;
        self.tracker_view = None;
        if !plan.is_none() {
            let t = plan.cast::<pyo3::types::PyTuple>()?;
            self.tracker_view = Some((t.get_item(0)?.extract()?, t.get_item(1)?.extract()?));
            self.plate_geoms = t.get_item(2)?.extract()?;
            self.anchored = t.get_item(3)?.extract()?;
        }
        Ok(())
    }

    /// `FootContactTracker.update` when it only stamps the contact time (the cached view
    /// holds this step's contacts, one of them the plate's, the anchor is set) or changes
    /// nothing (no plate contact, nothing remembered); false: the Python update must run.
    fn track_contact(&self, py: Python<'_>, ncon: i64) -> PyResult<bool> {
        let Some((view_ncon, view)) = &self.tracker_view else {
            return Ok(false);
        };
        if *view_ncon != ncon {
            return Ok(false);
        }
        let view = view.bind(py);
        // SAFETY: read only, no Python runs while the view lives (untracked.rs); a strided
        // view of MuJoCo's contact structs, hence the array view, not a slice.
        let plate = unsafe { view.as_array() }
            .iter()
            .any(|g| self.plate_geoms.contains(g));
        if !plate {
            // Contacts without the plate and nothing remembered: `_track(False)` resets a
            // reset tracker (no change). Anything remembered: Python releases it.
            return Ok(self.tracker_idle);
        }
        if !self.anchored {
            return Ok(false);
        }
        let time = self.names.time.f64(self.data.bind(py))?;
        self.names
            .last_contact_time
            .set(self.tracker.bind(py), time)?;
        Ok(true)
    }

    /// Write the flags back (before Python code runs).
    pub(crate) fn flush(&mut self, py: Python<'_>) -> PyResult<()> {
        if !self.dirty {
            return Ok(());
        }
        let p = self.plant.bind(py);
        let n = &self.names;
        n.stale.set(p, self.stale)?;
        n.needs_step1.set(p, self.needs_step1)?;
        n.state_version.set(p, self.version)?;
        self.dirty = false;
        Ok(())
    }

    /// `Plant.sync` when stale (no held external wrench: checked by `step_ok`'s users).
    pub(crate) fn fresh(&mut self, py: Python<'_>) -> PyResult<()> {
        self.ensure_loaded(py)?;
        if self.stale {
            self.stale = false;
            self.needs_step1 = false;
            self.dirty = true;
            self.forward
                .bind(py)
                .call1((self.model.bind(py), self.data.bind(py)))?;
        }
        Ok(())
    }

    /// True when the plant's `step(1)` can run here.
    pub(crate) fn step_ready(&mut self, py: Python<'_>) -> PyResult<bool> {
        self.ensure_loaded(py)?;
        Ok(self.step_ok)
    }

    /// True when a held external wrench is absent (the lazy forward needs no re-aim).
    pub(crate) fn sync_ready(&mut self, py: Python<'_>) -> PyResult<bool> {
        self.ensure_loaded(py)?;
        Ok(self.step_ok)
    }

    /// `Plant.step(1)` (requires `step_ready`).
    pub(crate) fn step(&mut self, py: Python<'_>) -> PyResult<()> {
        self.ensure_loaded(py)?;
        // Sensors only in the forward pass a reading runs, while the robot cannot fall
        // asleep in this step (`Plant.step`, lazy_sensors).
        let may_sleep = self
            .sleep
            .as_ref()
            .is_some_and(|s| s.bind(py).borrow().is_allowed());
        if self.sensor_bit == 0 || may_sleep {
            self.passes(py, None)?;
        } else {
            let flags = self.flags.get(py)?;
            self.flags.set(py, flags | self.sensor_bit)?;
            let passes = self.passes(py, Some(flags));
            self.flags.set(py, flags)?;
            passes?;
        }
        let d = self.data.bind(py);
        // FootContactTracker.update: returns at once with no contact and nothing to release.
        let ncon = self.names.ncon.i64(d)?;
        if ncon != 0 || !self.tracker_idle {
            if ncon != 0 && self.track_contact(py, ncon)? {
                self.tracker_fast += 1;
            } else {
                let tr = self.tracker.bind(py);
                self.names.update.get(tr)?.call1((d,))?;
                self.load_tracker(py)?;
                self.tracker_python += 1;
            }
        }
        if let Some(gate) = &self.gate {
            gate.bind(py).borrow_mut().update_now(py)?;
        }
        self.stale = true;
        self.needs_step1 = true;
        self.version += 1;
        self.dirty = true;
        Ok(())
    }

    /// `Plant._passes`: one step's MuJoCo passes with the rotor and sleep writes;
    /// `lazy`: the sensor bit is set; the flags without it.
    fn passes(&mut self, py: Python<'_>, lazy: Option<i64>) -> PyResult<()> {
        let m = self.model.bind(py);
        let d = self.data.bind(py);
        if self.stale || self.needs_step1 {
            self.step1.bind(py).call1((m, d))?;
        }
        self.needs_step1 = true;
        self.rotors.bind(py).borrow_mut().run(py, true)?;
        if let Some(sleep) = &self.sleep {
            // this step's controls written: the sleep rule (a changed control wakes now)
            let step1 = self.step1.bind(py);
            let mut sleep = sleep.bind(py).borrow_mut();
            sleep.run_before_step2(py, || step1.call1((m, d)).map(|_| ()))?;
            if let Some(flags) = lazy.filter(|_| sleep.is_allowed()) {
                // the robot may fall asleep in this step: its sensors as mj_step1 gives them
                self.flags.set(py, flags)?;
                self.sensor_pos.bind(py).call1((m, d))?;
                self.sensor_vel.bind(py).call1((m, d))?;
            }
        }
        self.step2.bind(py).call1((m, d))?;
        Ok(())
    }

    /// The plant's simulated time (`Plant.time`).
    pub(crate) fn time(&self, py: Python<'_>) -> PyResult<f64> {
        self.names.time.f64(self.data.bind(py))
    }

    /// `Plant.set_servo_targets(targets)`: finite goals into the servo controls after the
    /// lazy forward; non-finite ones keep the previous goal and are counted.
    pub(crate) fn set_servo_targets(&mut self, py: Python<'_>, targets: &[f64]) -> PyResult<()> {
        if targets.len() != self.servo_act.len() {
            return Err(pyo3::exceptions::PyValueError::new_err(format!(
                "q: expected {} values, got {}",
                self.servo_act.len(),
                targets.len()
            )));
        }
        let rejected = targets.iter().filter(|q| !q.is_finite()).count();
        if rejected > 0 {
            let p = self.plant.bind(py);
            let n = self.names.rejected_commands.i64(p)?;
            self.names
                .rejected_commands
                .set(p, n + i64::try_from(rejected).unwrap_or(i64::MAX))?;
        }
        self.fresh(py)?;
        // SAFETY: MuJoCo's ctrl, written here only; `targets` is the caller's Rust slice
        // and no Python runs while `ctrl` lives (untracked.rs).
        let ctrl = unsafe { untracked::write(self.ctrl.bind(py), "ctrl") }?;
        for (&a, &q) in self.servo_act.iter().zip(targets) {
            if q.is_finite() {
                *ctrl.get_mut(a).ok_or_else(|| {
                    pyo3::exceptions::PyIndexError::new_err("servo actuator out of range")
                })? = q;
            }
        }
        Ok(())
    }

    /// The rotors' ESC duty commands (`RotorPlantCore.command_duties`).
    pub(crate) fn command_duties(&self, py: Python<'_>, duties: &[f64]) -> PyResult<()> {
        self.rotors
            .bind(py)
            .borrow_mut()
            .kernel_command_duties(duties)
    }
}
