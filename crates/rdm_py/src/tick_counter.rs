//! `TickCounter`: the lockstep loop's next base tick, written by the Rust loop
//! (`LockstepKernel.run`) after every tick and readable by Python code during one
//! (`Lockstep.k`, `Lockstep.time` from inside a node's tick).

use std::sync::atomic::{AtomicU64, Ordering};

use pyo3::prelude::*;

/// The next base tick `k` of a lockstep loop (0 before the first).
#[pyclass(module = "rdm._rdm", frozen)]
#[derive(Default)]
pub struct TickCounter(AtomicU64);

impl TickCounter {
    /// Set the next base tick (Rust side).
    pub(crate) fn set(&self, k: u64) {
        self.0.store(k, Ordering::Relaxed);
    }
}

#[pymethods]
impl TickCounter {
    #[new]
    fn new() -> Self {
        TickCounter::default()
    }

    /// The next base tick.
    fn get(&self) -> u64 {
        self.0.load(Ordering::Relaxed)
    }
}

/// Register `TickCounter`.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<TickCounter>()?;
    Ok(())
}
