//! The plant side of the kernel: `rdm.plant.Plant`'s own Rust cores, shared with its Python
//! face: its step and lazy forward pass (`PlantStepCore`, the one form `Plant.step` and
//! `Plant.sync` run), its state (`PlantStateCore`: the flags, the rejected goals, whether a
//! step can run without Python) and its rotors, with the MjData views the bridge reads and
//! writes. Nothing is written back, nothing re-read.

use pyo3::prelude::*;

use crate::plant_state::PlantStateCore;
use crate::plant_step::PlantStepCore;
use crate::rotor_plant::RotorPlantCore;
use crate::untracked;

/// What `LockstepKernel.attach_plant` is given of an `rdm.plant.Plant` at construction
/// (typed; the caller reads them, the kernel holds them for the plant's lifetime).
pub(crate) struct PlantParts {
    pub(crate) stepper: Py<PlantStepCore>,
    pub(crate) state: Py<PlantStateCore>,
    pub(crate) rotors: Py<RotorPlantCore>,
    /// Plant's `_v_qpos`, `_v_sensordata`, `_v_ctrl` (views of MjData, stable for its life).
    pub(crate) qpos: Py<numpy::PyArray1<f64>>,
    pub(crate) sensordata: Py<numpy::PyArray1<f64>>,
    pub(crate) ctrl: Py<numpy::PyArray1<f64>>,
    /// Servo actuator index per joint (`Plant._servo_act`).
    pub(crate) servo_act: Vec<usize>,
}

/// One MuJoCo plant as the kernel drives it.
pub(crate) struct PlantLink {
    stepper: Py<PlantStepCore>,
    state: Py<PlantStateCore>,
    rotors: Py<RotorPlantCore>,
    pub(crate) qpos: Py<numpy::PyArray1<f64>>,
    pub(crate) sensordata: Py<numpy::PyArray1<f64>>,
    ctrl: Py<numpy::PyArray1<f64>>,
    servo_act: Vec<usize>,
}

impl PlantLink {
    pub(crate) fn new(parts: PlantParts) -> Self {
        PlantLink {
            stepper: parts.stepper,
            state: parts.state,
            rotors: parts.rotors,
            qpos: parts.qpos,
            sensordata: parts.sensordata,
            ctrl: parts.ctrl,
            servo_act: parts.servo_act,
        }
    }

    /// `Plant.sync` when stale (no held external wrench: checked by `step_ready`'s users).
    pub(crate) fn fresh(&mut self, py: Python<'_>) -> PyResult<()> {
        self.stepper.bind(py).borrow_mut().fresh(py)
    }

    /// True when the plant's `step(1)` and its lazy forward pass run without Python (rotors
    /// in the Rust core, no held external wrench).
    pub(crate) fn step_ready(&self, py: Python<'_>) -> bool {
        self.state.bind(py).borrow().state.step_in_core()
    }

    /// `Plant.step(1)` (requires `step_ready`).
    pub(crate) fn step(&mut self, py: Python<'_>) -> PyResult<()> {
        self.stepper.bind(py).borrow_mut().step_n(py, 1)
    }

    /// Contact tracker updates done in Rust / handed to its Python face (diagnostics).
    pub(crate) fn tracker_counts(&self, py: Python<'_>) -> (u64, u64) {
        self.stepper.bind(py).borrow().tracker_counts()
    }

    /// The plant's simulated time (`Plant.time`, MuJoCo's `data.time`).
    pub(crate) fn time(&self, py: Python<'_>) -> PyResult<f64> {
        self.stepper.bind(py).borrow().time(py)
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
