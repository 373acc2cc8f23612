//! The plant bridge's millisecond when no mocap sample is due (nor an IMU or truth sample
//! without a Rust path): the coupling of the bridge's one `PlantBridgeCore` (joints ->
//! Neurons, goals -> servo controls, ESC outputs -> rotor duties; the object
//! `PlantBridge.tick` ticks), then the IMU, foot wrench (lazy forward, noise, Leptrino) and
//! truth samples the core's schedule says are due.

use pyo3::prelude::*;
use pyo3::types::PyTuple;

use super::leptrino::LeptrinoFast;
use super::plant::PlantLink;
use crate::normal_stream::NormalStreamCore;
use crate::plant_bridge::PlantBridgeCore;
use crate::sensor_sim::{ImuNoiseCore, WrenchNoiseCore};
use crate::spinal_state::SpinalMirrorState;
use crate::untracked;
use rdm_core::estimate::ImuSample;
use rdm_core::sim::sample_schedule::Reading;

/// The next `N` normals of a noise model's stream (the object the model itself takes from).
fn take<const N: usize>(py: Python<'_>, stream: &Py<NormalStreamCore>) -> PyResult<[f64; N]> {
    let mut out = [0.0; N];
    stream.bind(py).borrow_mut().take_into(py, &mut out)?;
    Ok(out)
}

/// The IMU sample as the kernel takes it: into the Spinal mirror's state.
struct ImuPath {
    adr: (usize, usize, usize),
    core: Py<ImuNoiseCore>,
    normals: Py<NormalStreamCore>,
    /// The Spinal mirror's state (`SpinalMirror._state`).
    sink: Py<SpinalMirrorState>,
}

/// The bridge's sample paths (`rdm.nodes.lockstep_kernel`).
struct Plan {
    /// (force, torque) addresses in sensordata of the foot wrench sensor.
    wrench_adr: (usize, usize),
    wrench_core: Option<Py<WrenchNoiseCore>>,
    wrench_normals: Option<Py<NormalStreamCore>>,
    /// None: an IMU sample goes to the Python tick.
    imu: Option<ImuPath>,
    /// `PlantBridge._kernel_truth` (the ground-truth sample into its sink) and the parts it
    /// may change; None: a truth sample goes to the Python tick.
    truth: Option<(Py<PyAny>, u8)>,
}

/// What a fast bridge tick leaves to Python: the ground-truth call when a truth sample is
/// due.
pub(crate) struct BridgeOut {
    pub(crate) truth: Option<(Py<PyAny>, u8)>,
}

pub(crate) struct BridgeFast {
    /// Returns the plan tuple, or None when the tick has no Rust form now
    /// (`rdm.nodes.lockstep_kernel`).
    plan_of: Py<PyAny>,
    /// `PlantBridge._core`: the state, schedule and banks both tick forms use.
    core: Py<PlantBridgeCore>,
    plan: Option<Plan>,
    loaded: bool,
}

impl BridgeFast {
    pub(crate) fn new(core: Py<PlantBridgeCore>, plan_of: Py<PyAny>) -> Self {
        BridgeFast {
            plan_of,
            core,
            plan: None,
            loaded: false,
        }
    }

    pub(crate) fn invalidate(&mut self) {
        self.loaded = false;
    }

    fn ensure_loaded(&mut self, py: Python<'_>) -> PyResult<()> {
        if self.loaded {
            return Ok(());
        }
        let plan = self.plan_of.bind(py).call0()?;
        self.plan = if !plan.is_none() {
            let t = plan.cast_into::<PyTuple>()?;
            let normals = t.get_item(2)?;
            let wrench_normals = if normals.is_none() {
                None
            } else {
                Some(normals.cast_into::<NormalStreamCore>()?.unbind())
            };
            let imu = t.get_item(3)?;
            let imu = if imu.is_none() {
                None
            } else {
                let i = imu.cast::<PyTuple>()?;
                Some(ImuPath {
                    adr: i.get_item(0)?.extract()?,
                    core: i.get_item(1)?.cast_into::<ImuNoiseCore>()?.unbind(),
                    normals: i.get_item(2)?.cast_into::<NormalStreamCore>()?.unbind(),
                    sink: i.get_item(3)?.cast_into::<SpinalMirrorState>()?.unbind(),
                })
            };
            let truth = t.get_item(4)?;
            let truth = if truth.is_none() {
                None
            } else {
                let parts: Vec<String> = t.get_item(5)?.extract()?;
                Some((truth.unbind(), super::parts_mask(&parts)?))
            };
            let core = t.get_item(1)?;
            Some(Plan {
                wrench_adr: t.get_item(0)?.extract()?,
                wrench_core: if core.is_none() {
                    None
                } else {
                    Some(core.cast_into::<WrenchNoiseCore>()?.unbind())
                },
                wrench_normals,
                imu,
                truth,
            })
        } else {
            None
        };
        self.loaded = true;
        Ok(())
    }

    /// Whether the tick can run here: a plan, a constant battery already applied, and no
    /// mocap sample (nor IMU / truth sample without its path) due.
    pub(crate) fn ready(&mut self, py: Python<'_>) -> PyResult<bool> {
        self.ensure_loaded(py)?;
        let Some(p) = &self.plan else {
            return Ok(false);
        };
        let core = self.core.bind(py).borrow();
        if !core.state.battery_steady() {
            return Ok(false);
        }
        let due = core.schedule.bind(py).borrow().inner.peek();
        Ok((p.imu.is_some() || !due.has(Reading::Imu))
            && !due.has(Reading::Mocap)
            && (p.truth.is_some() || !due.has(Reading::Truth)))
    }

    /// `Plant.imu()` into the Spinal mirror's state (`SpinalMirror.set_imu_sample`, the
    /// sink of the plan).
    fn imu_sample_of(py: Python<'_>, imu: &mut ImuPath, plant: &mut PlantLink) -> PyResult<()> {
        plant.fresh(py)?;
        let ideal = {
            let sd = plant.sensordata.bind(py);
            // SAFETY: read only, no Python runs while `sd` lives (untracked.rs).
            let sd = unsafe { untracked::read(sd, "sensordata") }?;
            let three = |a: usize| -> PyResult<[f64; 3]> {
                sd.get(a..a + 3)
                    .and_then(|s| <[f64; 3]>::try_from(s).ok())
                    .ok_or_else(|| pyo3::exceptions::PyIndexError::new_err("IMU address"))
            };
            [three(imu.adr.0)?, three(imu.adr.1)?, three(imu.adr.2)?]
        };
        let normals = take::<9>(py, &imu.normals)?;
        let v = imu.core.get().inner.sample(&ideal, &normals).values;
        imu.sink.bind(py).try_borrow_mut()?.inner.imu = ImuSample {
            gyro: v[0],
            acc: v[1],
            mag: v[2],
        };
        Ok(())
    }

    /// The tick at `now` (requires `ready`); the foot wrench sample goes into the Leptrino
    /// stream state (the plan guarantees a Leptrino part when wrench samples are due).
    pub(crate) fn tick(
        &mut self,
        py: Python<'_>,
        now: f64,
        plant: &mut PlantLink,
        leptrino: Option<&LeptrinoFast>,
    ) -> PyResult<BridgeOut> {
        let Some(p) = &mut self.plan else {
            return Err(pyo3::exceptions::PyRuntimeError::new_err(
                "kernel: bridge tick without a plan",
            ));
        };
        // 1-4: the core's coupling, then the plant commands it asks for.
        let plant_time = plant.time(py)?;
        let mut core = self.core.bind(py).borrow_mut();
        let (targets_changed, duties_changed) = {
            // SAFETY: read only; kernel_couple is Rust and runs no Python (untracked.rs).
            let qpos = unsafe { untracked::read(plant.qpos.bind(py), "qpos") }?;
            core.kernel_couple(py, plant_time, now, qpos)?
        };
        if targets_changed {
            plant.set_servo_targets(py, &core.state.targets)?;
        }
        if duties_changed {
            plant.command_duties(py, &core.state.duties)?;
        }
        // 5-7: the IMU, the wrench, the truth (ready() excluded mocap).
        let due = core.schedule.bind(py).borrow_mut().inner.advance();
        drop(core);
        if due.has(Reading::Imu) {
            let imu = p.imu.as_mut().expect("ready() checked the IMU path");
            Self::imu_sample_of(py, imu, plant)?;
        }
        let truth = if due.has(Reading::Truth) {
            let (call, touches) = p.truth.as_ref().expect("ready() checked the truth path");
            Some((call.clone_ref(py), *touches))
        } else {
            None
        };
        if !due.has(Reading::Wrench) {
            return Ok(BridgeOut { truth });
        }
        plant.fresh(py)?;
        let normals = take::<6>(
            py,
            p.wrench_normals
                .as_ref()
                .expect("plan has the normals with the wrench"),
        )?;
        let ideal = {
            let sd = plant.sensordata.bind(py);
            // SAFETY: read only, no Python runs while `sd` lives (untracked.rs).
            let sd = unsafe { untracked::read(sd, "sensordata") }?;
            let (f, t) = p.wrench_adr;
            let get = |i: usize| {
                sd.get(i).copied().ok_or_else(|| {
                    pyo3::exceptions::PyIndexError::new_err("wrench address out of range")
                })
            };
            [
                get(f)?,
                get(f + 1)?,
                get(f + 2)?,
                get(t)?,
                get(t + 1)?,
                get(t + 2)?,
            ]
        };
        let core = p
            .wrench_core
            .as_ref()
            .expect("plan has the core with the wrench");
        let w = core.get().inner.sample(&ideal, &normals).values;
        let Some(l) = leptrino else {
            return Err(pyo3::exceptions::PyRuntimeError::new_err(
                "kernel: a bridge wrench sample without a Leptrino part",
            ));
        };
        l.set_wrench(py, w);
        Ok(BridgeOut { truth })
    }

    /// Nothing to write back: the bridge's state is its core's, the normal streams' are
    /// theirs.
    pub(crate) fn flush(&mut self, _py: Python<'_>) -> PyResult<()> {
        Ok(())
    }
}
