//! `PlantStepCore`: `rdm.plant.Plant`'s physics step and lazy forward pass (`Plant.step`,
//! `Plant.sync`), the one form both the plant's Python face and the lockstep kernel call.
//! Per step: `mj_step1` when the state needs it, the rotors (`RotorPlantCore`: ESC lags,
//! ceiling-scaled thrusts into ctrl), the held external wrenches, the sleep-at-rest rule
//! (`RestingSleepCore`), `mj_step2` with MuJoCo's sensors off while they cannot be read (lazy
//! sensors), the foot contact tracker (`FootTrackerCore`) and the collision gate
//! (`ContactGateCore`); the flags live in `PlantStateCore`. What only Python computes (a
//! ceiling model outside the rotor core, re-aiming held wrenches, a new contact view or
//! anchor) are callbacks of the face, called only when the state needs them.

use pyo3::prelude::*;

use crate::contact_gate::ContactGateCore;
use crate::foot_tracker::{FootTrackerCore, DONE};
use crate::option_flags::OptionFlags;
use crate::plant_state::PlantStateCore;
use crate::resting_sleep::RestingSleepCore;
use crate::rotor_plant::RotorPlantCore;

/// The face's callbacks (`rdm.plant.Plant`; each holds the plant weakly).
struct Callbacks {
    /// The rotors when a ceiling model is outside the core (ESC lags, thrusts into ctrl).
    rotors: Py<PyAny>,
    /// The held external wrenches into `xfrc_applied` at the bodies' present poses.
    apply_external: Py<PyAny>,
    /// Before a forward pass with held wrenches: kinematics, then the wrenches re-aimed.
    aim_external: Py<PyAny>,
    /// The tracker face's `update(data)` (a new contact view or anchor).
    tracker_update: Py<PyAny>,
}

/// The plant's step (see the module doc).
#[pyclass(module = "rdm._rdm", unsendable)]
pub struct PlantStepCore {
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
    gate: Option<Py<ContactGateCore>>,
    tracker: Py<FootTrackerCore>,
    sleep: Option<Py<RestingSleepCore>>,
    calls: Callbacks,
    /// Tracker updates done here / handed to the face (diagnostics).
    tracker_fast: u64,
    tracker_python: u64,
}

impl PlantStepCore {
    /// `Plant.sync` when stale.
    pub(crate) fn fresh(&mut self, py: Python<'_>) -> PyResult<()> {
        if self.state.bind(py).borrow().state.stale {
            self.sync_now(py)?;
        }
        Ok(())
    }

    fn sync_now(&mut self, py: Python<'_>) -> PyResult<()> {
        let held = {
            let mut s = self.state.bind(py).borrow_mut();
            s.state.synced();
            s.state.wrenches_held
        };
        if held {
            self.calls.aim_external.bind(py).call0()?;
        }
        self.forward
            .bind(py)
            .call1((self.model.bind(py), self.data.bind(py)))?;
        Ok(())
    }

    /// One physics step (`Plant.step(1)` but for the state's `stepped`).
    fn one_step(&mut self, py: Python<'_>) -> PyResult<()> {
        // Sensors only in the forward pass a reading runs, while the robot cannot fall
        // asleep in this step (it would keep values no step computed).
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
        // The contacts of this step's start: the slip anchor (the face builds a new contact
        // view or sets a new anchor).
        let d = self.data.bind(py);
        let ncon: i64 = d.getattr(pyo3::intern!(py, "ncon"))?.extract()?;
        let idle = self.tracker.bind(py).borrow().idle_now();
        if ncon != 0 || !idle {
            let time = self.time(py)?;
            let status = self.tracker.bind(py).borrow_mut().update_at(d, ncon, time);
            if status == DONE {
                self.tracker_fast += 1;
            } else {
                self.calls.tracker_update.bind(py).call1((d,))?;
                self.tracker_python += 1;
            }
        }
        if let Some(gate) = &self.gate {
            // contacts off for the next pass if none can occur in it
            gate.bind(py).borrow_mut().update_now(py)?;
        }
        Ok(())
    }

    /// One step's MuJoCo passes with this step's rotor, wrench and sleep writes; `lazy`:
    /// the sensor bit is set, these are the flags without it.
    fn passes(&mut self, py: Python<'_>, lazy: Option<i64>) -> PyResult<()> {
        let m = self.model.bind(py);
        let d = self.data.bind(py);
        let (in_core, held) = {
            let mut s = self.state.bind(py).borrow_mut();
            // false: a forward pass (sync) already ran on this very state: mj_step1's
            // position and velocity stages would recompute the same numbers (they depend on
            // neither ctrl nor xfrc_applied), so only mj_step2 runs (bit-identical).
            if s.state.begin_step() {
                drop(s);
                self.step1.bind(py).call1((m, d))?;
                s = self.state.bind(py).borrow_mut();
            }
            (s.state.rotors_in_core, s.state.wrenches_held)
        };
        if in_core {
            self.rotors.bind(py).borrow_mut().run(py, true)?;
        } else {
            self.calls.rotors.bind(py).call0()?;
        }
        if held {
            self.calls.apply_external.bind(py).call0()?;
        }
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

    /// MuJoCo's `data.time`.
    pub(crate) fn time(&self, py: Python<'_>) -> PyResult<f64> {
        self.data
            .bind(py)
            .getattr(pyo3::intern!(py, "time"))?
            .extract()
    }

    /// `step(n)`.
    pub(crate) fn step_n(&mut self, py: Python<'_>, n: i64) -> PyResult<()> {
        let r = (0..n).try_for_each(|_| self.one_step(py));
        // the forward pass runs when something reads (see sync)
        self.state.bind(py).borrow_mut().state.stepped();
        r
    }

    /// (tracker updates done here, handed to the face).
    pub(crate) fn tracker_counts(&self) -> (u64, u64) {
        (self.tracker_fast, self.tracker_python)
    }
}

#[pymethods]
impl PlantStepCore {
    /// The plant's parts, typed: `model`, `data`; `mj`: MuJoCo's `mj_step1`, `mj_step2`,
    /// `mj_forward`, `mj_sensorPos`, `mj_sensorVel`; `flags`: `(address of
    /// opt.disableflags, model._address, option_flags.SEARCH_BYTES)` (None: unknown);
    /// `opt`: `model.opt`; `sensor_bit`: the bit set in `opt.disableflags` while a step runs
    /// (0: none); the plant's state, rotor, collision-gate, tracker and sleep cores; the
    /// face's callbacks `rotors()`, `apply_external()`, `aim_external()` and the tracker
    /// face's `update(data)`.
    #[new]
    #[allow(clippy::too_many_arguments)]
    #[pyo3(signature = (model, data, mj, flags, opt, sensor_bit, state, rotors, gate, tracker, sleep, callbacks))]
    fn new(
        py: Python<'_>,
        model: Py<PyAny>,
        data: Py<PyAny>,
        mj: [Py<PyAny>; 5],
        flags: (Option<usize>, Option<usize>, usize),
        opt: Py<PyAny>,
        sensor_bit: i64,
        state: Py<PlantStateCore>,
        rotors: Py<RotorPlantCore>,
        gate: Option<Py<ContactGateCore>>,
        tracker: Py<FootTrackerCore>,
        sleep: Option<Py<RestingSleepCore>>,
        callbacks: [Py<PyAny>; 4],
    ) -> Self {
        let [step1, step2, forward, sensor_pos, sensor_vel] = mj;
        let [rotors_cb, apply_external, aim_external, tracker_update] = callbacks;
        PlantStepCore {
            model,
            data,
            step1,
            step2,
            forward,
            sensor_pos,
            sensor_vel,
            flags: OptionFlags::new(py, flags.0, flags.1, flags.2, opt),
            sensor_bit,
            state,
            rotors,
            gate,
            tracker,
            sleep,
            calls: Callbacks {
                rotors: rotors_cb,
                apply_external,
                aim_external,
                tracker_update,
            },
            tracker_fast: 0,
            tracker_python: 0,
        }
    }

    /// Advance `n` physics steps.
    fn step(&mut self, py: Python<'_>, n: i64) -> PyResult<()> {
        self.step_n(py, n)
    }

    /// The forward pass on the present state (held wrenches re-aimed first).
    fn sync(&mut self, py: Python<'_>) -> PyResult<()> {
        self.sync_now(py)
    }
}

/// Register `PlantStepCore`.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PlantStepCore>()?;
    Ok(())
}
