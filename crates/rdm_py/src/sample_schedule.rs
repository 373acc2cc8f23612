//! `SampleSchedule`: the plant bridge's sampling schedule
//! (`rdm_core::sim::sample_schedule`), shared by `PlantBridge` and the lockstep kernel.

use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

use rdm_core::sim::sample_schedule::{self as core, READINGS};

/// Which of the IMU, wrench, mocap and truth readings is due at which bridge tick.
#[pyclass(module = "rdm._rdm")]
pub struct SampleSchedule {
    pub(crate) inner: core::SampleSchedule,
}

#[pymethods]
impl SampleSchedule {
    /// Ticks between the samples of each reading (0: off); the schedule starts at tick 0.
    #[new]
    fn new(
        imu_every: i64,
        wrench_every: i64,
        mocap_every: i64,
        truth_every: i64,
    ) -> PyResult<Self> {
        let given = [
            ("imu_every", imu_every),
            ("wrench_every", wrench_every),
            ("mocap_every", mocap_every),
            ("truth_every", truth_every),
        ];
        let mut every = [0u64; READINGS];
        for (slot, (name, value)) in every.iter_mut().zip(given) {
            *slot = u64::try_from(value).map_err(|_| {
                PyValueError::new_err(format!("SampleSchedule: {name} {value} is below 0"))
            })?;
        }
        Ok(SampleSchedule {
            inner: core::SampleSchedule::new(every),
        })
    }

    /// Take the next tick: (imu, wrench, mocap, truth) due at it.
    fn advance(&mut self) -> (bool, bool, bool, bool) {
        let [a, b, c, d] = self.inner.advance().0;
        (a, b, c, d)
    }

    /// (imu, wrench, mocap, truth) due at the next tick, without taking it.
    fn peek(&self) -> (bool, bool, bool, bool) {
        let [a, b, c, d] = self.inner.peek().0;
        (a, b, c, d)
    }

    /// Ticks between the samples of (imu, wrench, mocap, truth); 0: off.
    #[getter]
    fn every(&self) -> (u64, u64, u64, u64) {
        let [a, b, c, d] = self.inner.every();
        (a, b, c, d)
    }

    /// Ticks taken so far.
    #[getter]
    fn count(&self) -> u64 {
        self.inner.count()
    }
}

/// Register `SampleSchedule`.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<SampleSchedule>()?;
    Ok(())
}
