//! The plant bridge's millisecond (`PlantBridge.tick`, boards of one bank) when no IMU,
//! mocap or ground-truth sample is due: joints -> Neurons, goals -> servo controls, ESC
//! outputs -> rotor duties, and the foot wrench sample (lazy forward, noise, Leptrino).

use pyo3::prelude::*;
use pyo3::types::PyTuple;

use super::attr::Name;
use super::leptrino::LeptrinoFast;
use super::plant::PlantLink;
use crate::neuron_bank::NeuronBank;
use crate::normal_stream::NormalStreamCore;
use crate::sample_schedule::SampleSchedule;
use crate::sensor_sim::{ImuNoiseCore, WrenchNoiseCore};
use crate::untracked;
use rdm_core::sim::sample_schedule::Reading;

/// The next `N` normals of a noise model's stream (the object the model itself takes from).
fn take<const N: usize>(py: Python<'_>, stream: &Py<NormalStreamCore>) -> PyResult<[f64; N]> {
    let mut out = [0.0; N];
    stream.bind(py).borrow_mut().take_into(py, &mut out)?;
    Ok(out)
}

/// The IMU sample as the kernel takes it: into the Spinal mirror's `gyro`/`acc`/`mag`.
struct ImuPath {
    adr: (usize, usize, usize),
    core: Py<ImuNoiseCore>,
    normals: Py<NormalStreamCore>,
    sink: Py<PyAny>,
}

/// The bridge's plan (`rdm.nodes.lockstep_kernel`).
struct Plan {
    time_mismatches: i64,
    half_period: f64,
    /// `PlantBridge.schedule`: its Python ticks and these advance the one counter, which is
    /// also the bridge's tick count.
    schedule: Py<SampleSchedule>,
    /// (force, torque) addresses in sensordata of the foot wrench sensor.
    wrench_adr: (usize, usize),
    wrench_core: Option<Py<WrenchNoiseCore>>,
    wrench_normals: Option<Py<NormalStreamCore>>,
    /// None: an IMU sample goes to the Python tick.
    imu: Option<ImuPath>,
    /// `PlantBridge._kernel_truth` (the ground-truth sample into its sink) and the parts it
    /// may change; None: a truth sample goes to the Python tick.
    truth: Option<(Py<PyAny>, u8)>,
    targets: Py<numpy::PyArray1<f64>>,
    duties: Py<numpy::PyArray1<f64>>,
}

struct Names {
    gyro: Name,
    acc: Name,
    mag: Name,
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
    /// `store(time_mismatches)`: the mismatch count back into the node.
    store: Py<PyAny>,
    names: Names,
    bank: Py<NeuronBank>,
    plan: Option<Plan>,
    loaded: bool,
    dirty: bool,
    scratch: Vec<f64>,
}

impl BridgeFast {
    pub(crate) fn new(
        py: Python<'_>,
        bank: Py<NeuronBank>,
        plan_of: Py<PyAny>,
        store: Py<PyAny>,
    ) -> Self {
        BridgeFast {
            plan_of,
            store,
            names: Names {
                gyro: Name::new(py, "gyro"),
                acc: Name::new(py, "acc"),
                mag: Name::new(py, "mag"),
            },
            bank,
            plan: None,
            loaded: false,
            dirty: false,
            scratch: Vec::with_capacity(16),
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
            let normals = t.get_item(5)?;
            let wrench_normals = if normals.is_none() {
                None
            } else {
                Some(normals.cast_into::<NormalStreamCore>()?.unbind())
            };
            let imu = t.get_item(8)?;
            let imu = if imu.is_none() {
                None
            } else {
                let i = imu.cast::<PyTuple>()?;
                Some(ImuPath {
                    adr: i.get_item(0)?.extract()?,
                    core: i.get_item(1)?.cast_into::<ImuNoiseCore>()?.unbind(),
                    normals: i.get_item(2)?.cast_into::<NormalStreamCore>()?.unbind(),
                    sink: i.get_item(3)?.unbind(),
                })
            };
            let truth = t.get_item(9)?;
            let truth = if truth.is_none() {
                None
            } else {
                let parts: Vec<String> = t.get_item(10)?.extract()?;
                Some((truth.unbind(), super::parts_mask(&parts)?))
            };
            let core = t.get_item(4)?;
            Some(Plan {
                time_mismatches: t.get_item(0)?.extract()?,
                half_period: t.get_item(1)?.extract()?,
                schedule: t.get_item(2)?.cast_into::<SampleSchedule>()?.unbind(),
                wrench_adr: t.get_item(3)?.extract()?,
                wrench_core: if core.is_none() {
                    None
                } else {
                    Some(core.cast_into::<WrenchNoiseCore>()?.unbind())
                },
                wrench_normals,
                imu,
                truth,
                targets: t.get_item(6)?.extract()?,
                duties: t.get_item(7)?.extract()?,
            })
        } else {
            None
        };
        self.loaded = true;
        Ok(())
    }

    /// Whether the tick can run here: a plan, and no IMU / mocap / truth sample due.
    pub(crate) fn ready(&mut self, py: Python<'_>) -> PyResult<bool> {
        self.ensure_loaded(py)?;
        let Some(p) = &self.plan else {
            return Ok(false);
        };
        let due = p.schedule.bind(py).borrow().inner.peek();
        Ok((p.imu.is_some() || !due.has(Reading::Imu))
            && !due.has(Reading::Mocap)
            && (p.truth.is_some() || !due.has(Reading::Truth)))
    }

    /// `Plant.imu()` into `SpinalMirror.set_imu_sample` (the sink of the plan).
    fn imu_sample_of(
        names: &Names,
        py: Python<'_>,
        imu: &mut ImuPath,
        plant: &mut PlantLink,
    ) -> PyResult<()> {
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
        let sink = imu.sink.bind(py);
        names.gyro.set(sink, PyTuple::new(py, v[0])?)?;
        names.acc.set(sink, PyTuple::new(py, v[1])?)?;
        names.mag.set(sink, PyTuple::new(py, v[2])?)?;
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
        self.dirty = true;
        if (plant.time(py)? - now).abs() > p.half_period {
            p.time_mismatches += 1;
        }
        // 1-4: the Rust coupling (bank.bridge_tick), then the plant commands it asks for.
        let (targets_changed, duties_changed) = {
            let (qpos, targets, duties) =
                (plant.qpos.bind(py), p.targets.bind(py), p.duties.bind(py));
            let apart = untracked::disjoint(targets, duties)
                && untracked::disjoint(targets, qpos)
                && untracked::disjoint(duties, qpos);
            if !apart {
                return Err(pyo3::exceptions::PyValueError::new_err(
                    "bridge arrays: targets, duties and qpos must not share memory",
                ));
            }
            // SAFETY: the three buffers are disjoint (checked above); kernel_bridge_tick is
            // Rust and runs no Python (untracked.rs).
            let (qpos, targets, duties) = unsafe {
                (
                    untracked::read(qpos, "qpos")?,
                    untracked::write(targets, "bridge targets")?,
                    untracked::write(duties, "bridge duties")?,
                )
            };
            self.bank
                .bind(py)
                .borrow_mut()
                .kernel_bridge_tick(qpos, targets, duties)?
        };
        if targets_changed {
            self.scratch.clear();
            // SAFETY: read only, copied out before any Python runs (untracked.rs).
            let targets = unsafe { untracked::read(p.targets.bind(py), "bridge targets") }?;
            self.scratch.extend_from_slice(targets);
            plant.set_servo_targets(py, &self.scratch)?;
        }
        if duties_changed {
            self.scratch.clear();
            // SAFETY: as for the targets.
            let duties = unsafe { untracked::read(p.duties.bind(py), "bridge duties") }?;
            self.scratch.extend_from_slice(duties);
            plant.command_duties(py, &self.scratch)?;
        }
        // 5-7: the IMU, the wrench, the truth (ready() excluded mocap).
        let due = p.schedule.bind(py).borrow_mut().inner.advance();
        if due.has(Reading::Imu) {
            let imu = p.imu.as_mut().expect("ready() checked the IMU path");
            Self::imu_sample_of(&self.names, py, imu, plant)?;
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

    /// Write the counters back (`store`).
    pub(crate) fn flush(&mut self, py: Python<'_>) -> PyResult<()> {
        if !self.dirty {
            return Ok(());
        }
        if let Some(p) = &self.plan {
            self.store.bind(py).call1((p.time_mismatches,))?;
        }
        self.dirty = false;
        Ok(())
    }
}
