//! `StopFlag`: the lockstep loop's stop request, set by a node's Python tick
//! (`Lockstep.stop`) and read by the Rust loop (`LockstepKernel.run`) after it.

use std::sync::atomic::{AtomicBool, Ordering};

use pyo3::prelude::*;

/// A stop request: `set()` asks the running loop to stop after the tick in progress.
#[pyclass(module = "rdm._rdm", frozen)]
#[derive(Default)]
pub struct StopFlag(AtomicBool);

impl StopFlag {
    /// Whether a stop was asked (Rust side).
    pub(crate) fn get(&self) -> bool {
        self.0.load(Ordering::Relaxed)
    }
}

#[pymethods]
impl StopFlag {
    #[new]
    fn new() -> Self {
        StopFlag::default()
    }

    /// Ask the loop to stop after the tick in progress.
    fn set(&self) {
        self.0.store(true, Ordering::Relaxed);
    }

    /// Withdraw the request (a loop run starts with it clear).
    fn clear(&self) {
        self.0.store(false, Ordering::Relaxed);
    }

    /// Whether a stop was asked.
    fn is_set(&self) -> bool {
        self.get()
    }
}

/// Register `StopFlag`.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<StopFlag>()?;
    Ok(())
}
