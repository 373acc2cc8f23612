//! `PlantStateCore`: `rdm_core::sim::plant_state::PlantState`, the plant's lazy-forward
//! flags, state version, rejected-goal count and whether a step can run in Rust. Its Python
//! face is `rdm.plant.Plant` (which reads and changes it through these methods); the lockstep
//! kernel's plant step changes the same object.

use pyo3::prelude::*;
use rdm_core::sim::plant_state::PlantState;

/// The plant's state between calls (see the module doc).
#[pyclass(module = "rdm._rdm")]
pub struct PlantStateCore {
    pub(crate) state: PlantState,
}

#[pymethods]
impl PlantStateCore {
    /// A fresh plant: not stale, its first step runs `mj_step1`, version 0.
    #[new]
    fn new() -> Self {
        PlantStateCore {
            state: PlantState::new(),
        }
    }

    /// True after a step until the lazy `mj_forward` ran.
    #[getter]
    fn stale(&self) -> bool {
        self.state.stale
    }

    #[setter]
    fn set_stale(&mut self, on: bool) {
        self.state.stale = on;
    }

    /// The next step runs `mj_step1`.
    #[getter]
    fn needs_step1(&self) -> bool {
        self.state.needs_step1
    }

    #[setter]
    fn set_needs_step1(&mut self, on: bool) {
        self.state.needs_step1 = on;
    }

    /// Changes with every step, reset and outside access to the data.
    #[getter]
    fn version(&self) -> u64 {
        self.state.version
    }

    /// Non-finite servo goals refused.
    #[getter]
    fn rejected_commands(&self) -> u64 {
        self.state.rejected_commands
    }

    /// Every rotor's ceiling model is in the Rust rotor core.
    #[getter]
    fn rotors_in_core(&self) -> bool {
        self.state.rotors_in_core
    }

    #[setter]
    fn set_rotors_in_core(&mut self, on: bool) {
        self.state.rotors_in_core = on;
    }

    /// An external wrench is held.
    #[getter]
    fn wrenches_held(&self) -> bool {
        self.state.wrenches_held
    }

    #[setter]
    fn set_wrenches_held(&mut self, on: bool) {
        self.state.wrenches_held = on;
    }

    /// A forward pass ran on the present state (`Plant.sync`).
    fn synced(&mut self) {
        self.state.synced();
    }

    /// The caller may change the state (`Plant.data`).
    fn touched(&mut self) {
        self.state.touched();
    }

    /// The plant was reset (`Plant.reset`).
    fn reset(&mut self) {
        self.state.reset();
    }

    /// One step's passes begin: whether `mj_step1` must run.
    fn begin_step(&mut self) -> bool {
        self.state.begin_step()
    }

    /// Steps ran (`Plant.step`).
    fn stepped(&mut self) {
        self.state.stepped();
    }

    /// Count `n` refused servo goals.
    fn reject(&mut self, n: u64) {
        self.state.reject(n);
    }
}

/// Register `PlantStateCore`.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PlantStateCore>()?;
    Ok(())
}
