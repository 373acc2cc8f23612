//! `PlantBridgeCore`: the plant bridge's state (`rdm_core::sim::bridge_state`), its sampling
//! schedule and the Neuron banks it couples, in one object. `rdm.nodes.plant_bridge.PlantBridge`
//! ticks it from Python and the lockstep kernel (`crate::kernel`) ticks the same object, so
//! the bridge has one state and one coupling.

use numpy::{PyArray1, PyReadonlyArray1};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

use crate::neuron_bank::NeuronBank;
use crate::sample_schedule::SampleSchedule;
use rdm_core::sim::bridge_state::BridgeState;

/// The plant bridge's state, schedule and banks (see the module doc).
#[pyclass(module = "rdm._rdm")]
pub struct PlantBridgeCore {
    pub(crate) state: BridgeState,
    pub(crate) schedule: Py<SampleSchedule>,
    banks: Vec<Py<NeuronBank>>,
}

#[pymethods]
impl PlantBridgeCore {
    /// Servo targets start at `targets` (rad, one per plant joint), `rotors` duties at 0.5;
    /// a tick is `period` s (> 0); `schedule` is the sampling schedule; `banks` the Neuron
    /// banks with their bridge coupling attached (`NeuronBank.attach_bridge`), in order.
    #[new]
    fn new(
        targets: Vec<f64>,
        rotors: usize,
        period: f64,
        schedule: Py<SampleSchedule>,
        banks: Vec<Py<NeuronBank>>,
    ) -> PyResult<Self> {
        if !(period.is_finite() && period > 0.0) {
            return Err(PyValueError::new_err(format!(
                "PlantBridgeCore: period {period} must be finite and > 0"
            )));
        }
        Ok(PlantBridgeCore {
            state: BridgeState::new(&targets, rotors, period),
            schedule,
            banks,
        })
    }

    /// Steps 1, 2 and 4 of a bridge tick at `now` with the plant at `plant_time` and its
    /// `qpos`: counts a time mismatch, then each bank snapshots the joints and writes its
    /// changed goals into `targets` and ESC outputs into `duties`; returns
    /// `(targets_changed, duties_changed)`.
    fn couple(
        &mut self,
        py: Python<'_>,
        plant_time: f64,
        now: f64,
        qpos: PyReadonlyArray1<'_, f64>,
    ) -> PyResult<(bool, bool)> {
        let qpos = qpos
            .as_slice()
            .map_err(|_| PyValueError::new_err("qpos: must be C-contiguous"))?;
        self.kernel_couple(py, plant_time, now, qpos)
    }

    /// The servo targets (rad) last written (a copy).
    #[getter]
    fn targets<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_slice(py, &self.state.targets)
    }

    /// The rotor duties last written (a copy).
    #[getter]
    fn duties<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_slice(py, &self.state.duties)
    }

    /// The sampling schedule (the one object both tick forms advance).
    #[getter]
    fn schedule(&self, py: Python<'_>) -> Py<SampleSchedule> {
        self.schedule.clone_ref(py)
    }

    /// Ticks that found the plant more than half a period away from the tick's time.
    #[getter]
    fn time_mismatches(&self) -> u64 {
        self.state.time_mismatches()
    }

    /// The battery is the constant `volts` (a float) or a function of time (None) from now on.
    fn set_fixed_battery(&mut self, volts: Option<f64>) {
        self.state.set_fixed_battery(volts);
    }

    /// Take `volts` as this tick's voltage; True if it differs from the last applied.
    fn apply_voltage(&mut self, volts: f64) -> bool {
        self.state.apply_voltage(volts)
    }

    /// The last voltage applied (None before the first tick).
    #[getter]
    fn voltage(&self) -> Option<f64> {
        self.state.voltage()
    }

    /// True when the battery is a constant already applied.
    #[getter]
    fn battery_steady(&self) -> bool {
        self.state.battery_steady()
    }
}

/// The kernel's access (`crate::kernel::bridge`): the same work on slices.
impl PlantBridgeCore {
    /// [`PlantBridgeCore::couple`] on a qpos slice.
    pub(crate) fn kernel_couple(
        &mut self,
        py: Python<'_>,
        plant_time: f64,
        now: f64,
        qpos: &[f64],
    ) -> PyResult<(bool, bool)> {
        self.state.check_time(plant_time, now);
        let (mut targets_changed, mut duties_changed) = (false, false);
        for bank in &self.banks {
            let (t, d) = bank.bind(py).borrow_mut().kernel_bridge_tick(
                qpos,
                &mut self.state.targets,
                &mut self.state.duties,
            )?;
            targets_changed |= t;
            duties_changed |= d;
        }
        Ok((targets_changed, duties_changed))
    }
}

/// Register `PlantBridgeCore`.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PlantBridgeCore>()?;
    Ok(())
}
