//! The plant side of the kernel: `rdm.plant.Plant`'s lazy forward pass and its one-step
//! physics (`Plant.sync`, `Plant.step(1)`) on the plant's own Rust cores: its state
//! (`PlantStateCore`: the lazy-forward flags, the version, the rejected goals), the foot
//! contact tracker (`FootTrackerCore`), the rotors, the collision gate and the sleep-at-rest
//! rule (`RestingSleepCore`). The kernel shares these objects with the plant's Python face:
//! nothing is written back, nothing re-read.

use pyo3::prelude::*;

use super::option_flags::OptionFlags;
use crate::contact_gate::ContactGateCore;
use crate::foot_tracker::{FootTrackerCore, DONE};
use crate::plant_state::PlantStateCore;
use crate::resting_sleep::RestingSleepCore;
use crate::rotor_plant::RotorPlantCore;
use crate::untracked;

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
    /// The bit set in `opt.disableflags` while a step runs (`Plant._sensor_bit`; 0: none).
    pub(crate) sensor_bit: i64,
    pub(crate) state: Py<PlantStateCore>,
    pub(crate) rotors: Py<RotorPlantCore>,
    pub(crate) gate: Option<Py<ContactGateCore>>,
    /// The foot contact tracker's core and its face's `update(data)` (which builds a contact
    /// view or sets the anchor when the core asks for it).
    pub(crate) tracker: Py<FootTrackerCore>,
    pub(crate) tracker_update: Py<PyAny>,
    pub(crate) qpos: Py<numpy::PyArray1<f64>>,
    pub(crate) sensordata: Py<numpy::PyArray1<f64>>,
    pub(crate) ctrl: Py<numpy::PyArray1<f64>>,
    pub(crate) servo_act: Vec<usize>,
    /// `Plant.sleep`'s core (the robot's sleep at rest), when the plant has it.
    pub(crate) sleep: Option<Py<RestingSleepCore>>,
}

/// One MuJoCo plant as the kernel drives it.
pub(crate) struct PlantLink {
    model: Py<PyAny>,
    data: Py<PyAny>,
    step1: Py<PyAny>,
    step2: Py<PyAny>,
    forward: Py<PyAny>,
    sensor_pos: Py<PyAny>,
    sensor_vel: Py<PyAny>,
    /// `model.opt.disableflags`, which get `sensor_bit` while a step runs.
    flags: OptionFlags,
    sensor_bit: i64,
    state: Py<PlantStateCore>,
    rotors: Py<RotorPlantCore>,
    /// `Plant._contact_gate` (None: contacts always on).
    gate: Option<Py<ContactGateCore>>,
    tracker: Py<FootTrackerCore>,
    tracker_update: Py<PyAny>,
    /// Plant's `_v_qpos`, `_v_sensordata`, `_v_ctrl` (views of MjData, stable for its life).
    pub(crate) qpos: Py<numpy::PyArray1<f64>>,
    pub(crate) sensordata: Py<numpy::PyArray1<f64>>,
    pub(crate) ctrl: Py<numpy::PyArray1<f64>>,
    /// Servo actuator index per joint (`Plant._servo_act`).
    servo_act: Vec<usize>,
    /// `Plant.sleep`'s core (the robot's sleep at rest), when the plant has it.
    sleep: Option<Py<RestingSleepCore>>,
    /// Tracker updates done here / handed to the face's `update` (diagnostics).
    pub(crate) tracker_fast: u64,
    pub(crate) tracker_python: u64,
}

impl PlantLink {
    pub(crate) fn new(py: Python<'_>, parts: PlantParts) -> Self {
        let [step1, step2, forward, sensor_pos, sensor_vel] = parts.mj;
        PlantLink {
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
            sensor_bit: parts.sensor_bit,
            state: parts.state,
            rotors: parts.rotors,
            gate: parts.gate,
            tracker: parts.tracker,
            tracker_update: parts.tracker_update,
            qpos: parts.qpos,
            sensordata: parts.sensordata,
            ctrl: parts.ctrl,
            servo_act: parts.servo_act,
            sleep: parts.sleep,
            tracker_fast: 0,
            tracker_python: 0,
        }
    }

    /// `Plant.sync` when stale (no held external wrench: checked by `step_ready`'s users).
    pub(crate) fn fresh(&mut self, py: Python<'_>) -> PyResult<()> {
        let stale = {
            let mut s = self.state.bind(py).borrow_mut();
            let stale = s.state.stale;
            if stale {
                s.state.synced();
            }
            stale
        };
        if stale {
            self.forward
                .bind(py)
                .call1((self.model.bind(py), self.data.bind(py)))?;
        }
        Ok(())
    }

    /// True when the plant's `step(1)` and its lazy forward pass can run here (rotors in the
    /// Rust core, no held external wrench).
    pub(crate) fn step_ready(&self, py: Python<'_>) -> bool {
        self.state.bind(py).borrow().state.step_in_core()
    }

    /// `Plant.step(1)` (requires `step_ready`).
    pub(crate) fn step(&mut self, py: Python<'_>) -> PyResult<()> {
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
        // FootContactTracker.update: the core's rule; the face builds a new contact view or
        // sets a new anchor.
        let ncon: i64 = d.getattr(pyo3::intern!(py, "ncon"))?.extract()?;
        let idle = self.tracker.bind(py).borrow().idle_now();
        if ncon != 0 || !idle {
            let time = self.time(py)?;
            let status = self.tracker.bind(py).borrow_mut().update_at(d, ncon, time);
            if status == DONE {
                self.tracker_fast += 1;
            } else {
                self.tracker_update.bind(py).call1((d,))?;
                self.tracker_python += 1;
            }
        }
        if let Some(gate) = &self.gate {
            gate.bind(py).borrow_mut().update_now(py)?;
        }
        self.state.bind(py).borrow_mut().state.stepped();
        Ok(())
    }

    /// `Plant._passes`: one step's MuJoCo passes with the rotor and sleep writes;
    /// `lazy`: the sensor bit is set; the flags without it.
    fn passes(&mut self, py: Python<'_>, lazy: Option<i64>) -> PyResult<()> {
        let m = self.model.bind(py);
        let d = self.data.bind(py);
        if self.state.bind(py).borrow_mut().state.begin_step() {
            self.step1.bind(py).call1((m, d))?;
        }
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

    /// The plant's simulated time (`Plant.time`, MuJoCo's `data.time`).
    pub(crate) fn time(&self, py: Python<'_>) -> PyResult<f64> {
        self.data
            .bind(py)
            .getattr(pyo3::intern!(py, "time"))?
            .extract()
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
            self.state
                .bind(py)
                .borrow_mut()
                .state
                .reject(u64::try_from(rejected).unwrap_or(u64::MAX));
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
