//! `LockstepKernel`: the lockstep loop behind `rdm.nodes.lockstep.Lockstep`.
//!
//! Per base tick `k` (simulated time `k * dt`): every node due at `k`
//! (`rdm_core::sim::tick_schedule`) ticks in list order, the barriers settle, the physics
//! steps once; a paced run then sleeps to its real-time factor and reports progress. For the
//! nodes of the simulated stack that spend most milliseconds in a steady state (plant bridge,
//! Neuron bank, Spinal's idle CAN ms, Leptrino streaming, the plant step) an attached fast
//! part runs that state here, on the Rust cores the Python nodes already use; everything
//! else (a node outside its steady state, the onboard PC, loggers, scripts, every node of a
//! loop without parts) is the node's own Python `tick`.
//!
//! Exactness rule: the Python-visible state a fast path changes is written back (`flush`)
//! before any Python code runs, and every plan is re-read (`invalidate`) after, so Python
//! code always sees what the node's own ticks would have left. A part whose state is a Rust
//! core the node shares (Leptrino stream, Neuron bank, the plant's state and foot contact
//! tracker, resting sleep, normal streams) has nothing to write back but the Leptrino's
//! pending UART bytes.

mod attr;
mod bank;
mod bridge;
mod leptrino;
mod pacing;
mod plant;
mod run_loop;
mod spinal;

use pyo3::prelude::*;

use crate::can_master::{CanMaster, CanWire};
use crate::leptrino_sensor::LeptrinoStreamCore;
use crate::neuron_bank::NeuronBank;
use crate::plant_bridge::PlantBridgeCore;
use crate::plant_state::PlantStateCore;
use crate::plant_step::PlantStepCore;
use crate::rotor_plant::RotorPlantCore;
use crate::spinal_state::SpinalMirrorState;
use crate::stop_flag::StopFlag;
use crate::tick_counter::TickCounter;
use bank::BankFast;
use bridge::BridgeFast;
use leptrino::LeptrinoFast;
use pacing::Pacing;
use plant::{PlantLink, PlantParts};
use rdm_core::sim::tick_schedule::TickSchedule;

use spinal::{SpinalFast, SpinalTick};

/// What a Python call may change, as a mask of the fast parts it invalidates.
const PLANT: u8 = 1;
const BRIDGE: u8 = 2;
const BANK: u8 = 4;
const SPINAL: u8 = 8;
const LEPTRINO: u8 = 16;
const ALL: u8 = PLANT | BRIDGE | BANK | SPINAL | LEPTRINO;

/// A fast part as a Python call's boundary handles it: its deferred state written back,
/// its plan forgotten.
trait Part {
    fn flush(&mut self, py: Python<'_>) -> PyResult<()>;
    fn invalidate(&mut self);
}

macro_rules! part {
    ($t:ty) => {
        impl Part for $t {
            fn flush(&mut self, py: Python<'_>) -> PyResult<()> {
                <$t>::flush(self, py)
            }
            fn invalidate(&mut self) {
                <$t>::invalidate(self)
            }
        }
    };
}
part!(BridgeFast);
part!(BankFast);
part!(SpinalFast);
part!(LeptrinoFast);

#[derive(Clone, Copy, PartialEq, Eq)]
enum Kind {
    Python,
    Bridge,
    Bank,
    Spinal,
    Leptrino,
}

/// Ticks that ran on a fast path and in Python, per node (diagnostics).
#[derive(Clone, Default)]
struct Counts {
    fast: Vec<u64>,
    python: Vec<u64>,
    /// With `profile`: wall ns per node on each path, and of the physics steps.
    fast_ns: Vec<u64>,
    python_ns: Vec<u64>,
    physics_ns: u64,
    barriers_ns: u64,
}

/// The lockstep loop with fast paths (see the module doc).
#[pyclass(module = "rdm._rdm", unsendable)]
pub struct LockstepKernel {
    dt: f64,
    schedule: TickSchedule,
    ticks: Vec<Py<PyAny>>,
    /// `settle()` of each barrier, after the nodes of every tick.
    barriers: Vec<Py<PyAny>>,
    pacing: Pacing,
    base_ticks: u64,
    kinds: Vec<Kind>,
    /// Per node, whether its fast path may run this `run` (false: its `tick` attribute is
    /// not the class's own method, e.g. a wrapper a test installed).
    own_tick: Vec<bool>,
    /// Per node, the parts its Python tick may change (default: all).
    touches: Vec<u8>,
    physics: Option<Py<PyAny>>,
    clock: Py<PyAny>,
    stop: Py<StopFlag>,
    /// `k` as Python code reads it during a run.
    counter: Py<TickCounter>,
    k: u64,
    clock_t: Option<f64>,
    plant: Option<PlantLink>,
    bridge: Option<BridgeFast>,
    bank: Option<BankFast>,
    spinal: Option<SpinalFast>,
    leptrino: Option<LeptrinoFast>,
    counts: Counts,
    physics_fast: u64,
    physics_python: u64,
    boundaries: u64,
    /// Time every node tick and physics step (`stats()`'s `*_ns`).
    profile: bool,
}

#[pymethods]
impl LockstepKernel {
    /// Nodes named `names` with `periods` [s] and `offsets` [base ticks] (a node ticks at
    /// the base ticks `k` with `k % round(period / dt) == offset`); `ticks[i]`: node `i`'s
    /// `tick`; `physics`: the physics `step` (or None); `clock`: the `SimClock` the loop
    /// sets; `stop`: the loop's stop request; `counter`: where the next base tick is
    /// published after every tick (it starts at 0); `barriers`: `settle` callables run after the
    /// nodes of every tick; `speed`: the real-time factor to pace to (None: as fast as
    /// possible); `progress(sim_time, wall_time, ticks, real_time_factor)` every
    /// `progress_every` simulated seconds; `wall_clock`/`sleep`: injectable for tests (None:
    /// the process's monotonic clock and sleep).
    #[new]
    #[allow(clippy::too_many_arguments)]
    #[pyo3(signature = (dt, names, periods, offsets, ticks, physics, clock, stop, counter, barriers=Vec::new(), speed=None, progress=None, progress_every=1.0, profile=false, wall_clock=None, sleep=None))]
    fn new(
        dt: f64,
        names: Vec<String>,
        periods: Vec<f64>,
        offsets: Vec<u64>,
        ticks: Vec<Py<PyAny>>,
        physics: Option<Py<PyAny>>,
        clock: Py<PyAny>,
        stop: Py<StopFlag>,
        counter: Py<TickCounter>,
        barriers: Vec<Py<PyAny>>,
        speed: Option<f64>,
        progress: Option<Py<PyAny>>,
        progress_every: f64,
        profile: bool,
        wall_clock: Option<Py<PyAny>>,
        sleep: Option<Py<PyAny>>,
    ) -> PyResult<Self> {
        let n = ticks.len();
        if names.len() != n {
            return Err(pyo3::exceptions::PyValueError::new_err(
                "Lockstep: one name, period, offset and tick per node",
            ));
        }
        let schedule = TickSchedule::new(dt, &periods, &offsets).map_err(|e| {
            let who = e
                .index()
                .and_then(|i| names.get(i))
                .map_or(String::new(), |name| format!("node {name:?} "));
            pyo3::exceptions::PyValueError::new_err(format!("Lockstep: {who}{e}"))
        })?;
        let pacing = Pacing::new(speed, progress, progress_every, wall_clock, sleep)?;
        counter.get().set(0);
        Ok(LockstepKernel {
            dt,
            schedule,
            barriers,
            pacing,
            base_ticks: 0,
            kinds: vec![Kind::Python; n],
            own_tick: vec![true; n],
            touches: vec![ALL; n],
            ticks,
            physics,
            clock,
            stop,
            counter,
            k: 0,
            clock_t: None,
            plant: None,
            bridge: None,
            bank: None,
            spinal: None,
            leptrino: None,
            counts: Counts {
                fast: vec![0; n],
                python: vec![0; n],
                fast_ns: vec![0; n],
                python_ns: vec![0; n],
                physics_ns: 0,
                barriers_ns: 0,
            },
            profile,
            physics_fast: 0,
            physics_python: 0,
            boundaries: 0,
        })
    }

    /// The plant (`rdm.plant.Plant`) the physics step and the bridge drive, as its parts
    /// (read by the caller, `rdm.nodes.lockstep_kernel`): its step, state and rotor cores,
    /// the qpos, sensordata and ctrl views and the servo actuator per joint.
    #[allow(clippy::too_many_arguments)]
    fn attach_plant(
        &mut self,
        stepper: Py<PlantStepCore>,
        state: Py<PlantStateCore>,
        rotors: Py<RotorPlantCore>,
        qpos: Py<numpy::PyArray1<f64>>,
        sensordata: Py<numpy::PyArray1<f64>>,
        ctrl: Py<numpy::PyArray1<f64>>,
        servo_act: Vec<usize>,
    ) {
        self.plant = Some(PlantLink::new(PlantParts {
            stepper,
            state,
            rotors,
            qpos,
            sensordata,
            ctrl,
            servo_act,
        }));
    }

    /// Node `index` is a `PlantBridge` whose state is `core` (`PlantBridge._core`, needs
    /// `attach_plant`); `plan()` returns its sample paths, or None when its tick has no Rust
    /// form now.
    fn attach_bridge(
        &mut self,
        index: usize,
        core: Py<PlantBridgeCore>,
        plan: Py<PyAny>,
    ) -> PyResult<()> {
        self.check_index(index)?;
        self.bridge = Some(BridgeFast::new(core, plan));
        self.kinds[index] = Kind::Bridge;
        self.touches[index] = BRIDGE | PLANT | LEPTRINO;
        Ok(())
    }

    /// Node `index` is a `NeuronBankNode` whose Rust bank `bank` ticks on `wire`.
    fn attach_bank(
        &mut self,
        index: usize,
        bank: Py<NeuronBank>,
        wire: Py<CanWire>,
    ) -> PyResult<()> {
        self.check_index(index)?;
        self.bank = Some(BankFast::new(bank, wire));
        self.kinds[index] = Kind::Bank;
        self.touches[index] = BANK;
        Ok(())
    }

    /// Node `index` is a `SpinalMirror` with the clock and battery state `state` whose Rust
    /// CAN master `master` ticks on `wire`.
    #[allow(clippy::too_many_arguments)]
    fn attach_spinal(
        &mut self,
        index: usize,
        node: &Bound<'_, PyAny>,
        state: Py<SpinalMirrorState>,
        master: Py<CanMaster>,
        wire: Py<CanWire>,
        drain_at: usize,
    ) -> PyResult<()> {
        self.check_index(index)?;
        self.spinal = Some(SpinalFast::new(node, state, master, wire, drain_at));
        self.kinds[index] = Kind::Spinal;
        self.touches[index] = SPINAL;
        Ok(())
    }

    /// Node `index` is a `LeptrinoSensorNode` whose stream state is `stream`; `idle()` says
    /// whether its UART is an open in-process pipe with no host bytes waiting, and
    /// `write(data, marks)` is that UART's `write_marked`.
    fn attach_leptrino(
        &mut self,
        index: usize,
        stream: Py<LeptrinoStreamCore>,
        idle: Py<PyAny>,
        write: Py<PyAny>,
    ) -> PyResult<()> {
        self.check_index(index)?;
        self.leptrino = Some(LeptrinoFast::new(stream, idle, write));
        self.kinds[index] = Kind::Leptrino;
        self.touches[index] = LEPTRINO;
        Ok(())
    }

    /// What node `index`'s Python tick may read or change, by part name (`"plant"`,
    /// `"bridge"`, `"bank"`, `"spinal"`, `"leptrino"`); the default is every part. Only
    /// these parts' deferred state is written back before it runs, and only their plans are
    /// re-read after (a part left out must be neither read nor changed by it: the logs
    /// would differ from those of the nodes' own ticks).
    fn set_touches(&mut self, index: usize, parts: Vec<String>) -> PyResult<()> {
        self.check_index(index)?;
        self.touches[index] = parts_mask(&parts)?;
        Ok(())
    }

    /// Advance `n` base ticks (fewer if the stop request is set during a tick); `paced`:
    /// with pacing and progress reports (a run), else without (a single step). `ticks[i]`
    /// is node `i`'s present `tick` and `own[i]` whether it is the class's own method (a node
    /// whose `tick` was replaced runs only the replacement). Every deferred state is
    /// written back before it returns, also when a node raises (then `k` is the tick that
    /// raised). Returns the next `k`.
    #[pyo3(signature = (n, ticks, own, paced=true))]
    fn run(
        &mut self,
        py: Python<'_>,
        n: i64,
        ticks: Vec<Py<PyAny>>,
        own: Vec<bool>,
        paced: bool,
    ) -> PyResult<u64> {
        if ticks.len() != self.ticks.len() || own.len() != self.ticks.len() {
            return Err(pyo3::exceptions::PyValueError::new_err(
                "LockstepKernel.run: one tick and one flag per node",
            ));
        }
        self.ticks = ticks;
        self.own_tick = own;
        let k0 = self.k;
        self.clock_t = None;
        self.invalidate(ALL);
        if paced {
            self.pacing.begin(py, k0 as f64 * self.dt)?;
        }
        let r = self.run_inner(py, n, paced);
        self.base_ticks += self.k - k0;
        let last_t = self.k.saturating_sub(1) as f64 * self.dt;
        let f = self.flush(py, ALL);
        if r.is_ok() && self.k > k0 && self.clock_t != Some(last_t) {
            self.clock.bind(py).setattr("now", last_t)?;
        }
        let w = if paced { self.pacing.end(py) } else { Ok(()) };
        r?;
        f?;
        w?;
        Ok(self.k)
    }

    /// Time every node tick, the barriers and the physics step from this call on (`stats()`'s
    /// `fast_ns`, `python_ns` per node, `barriers_ns` and `physics_ns`: wall ns, each
    /// tick's flush and re-reads included in the node that caused them).
    #[setter]
    fn set_profile(&mut self, on: bool) {
        self.profile = on;
    }

    #[getter]
    fn profile(&self) -> bool {
        self.profile
    }

    /// The next base tick (after `run`, also when it raised).
    #[getter]
    fn k(&self) -> u64 {
        self.k
    }

    /// `{"fast": [...], "python": [...], "physics_fast": n, "physics_python": n,
    /// "boundaries": n, "base_ticks": n, "wall_time": s, ..., "spinal_busy": {...}}`: ticks
    /// per node index on each path, base ticks run, wall seconds of the paced runs;
    /// `spinal_busy`: the Spinal busy-ms work done here (`steps`, `battery_samples`,
    /// `imu_frames`, `servo_frames`), the ticks handed to the mirror's continuations
    /// (`finish_step`, `finish_publish`), and the ms the mirror received in Python with the
    /// rest run here / there (`receive_then_kernel`, `receive_then_python`; a Spinal tick
    /// counts as fast when its rest ran here).
    fn stats<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, pyo3::types::PyDict>> {
        let d = pyo3::types::PyDict::new(py);
        d.set_item("fast", self.counts.fast.clone())?;
        d.set_item("python", self.counts.python.clone())?;
        d.set_item("physics_fast", self.physics_fast)?;
        d.set_item("physics_python", self.physics_python)?;
        d.set_item("boundaries", self.boundaries)?;
        d.set_item("base_ticks", self.base_ticks)?;
        d.set_item("wall_time", self.pacing.wall_time)?;
        let (tf, tp) = self.plant.as_ref().map_or((0, 0), |p| p.tracker_counts(py));
        d.set_item("tracker_fast", tf)?;
        d.set_item("tracker_python", tp)?;
        let sc = self.spinal.as_ref().map(|s| s.counts).unwrap_or_default();
        let spinal = pyo3::types::PyDict::new(py);
        spinal.set_item("steps", sc.steps)?;
        spinal.set_item("battery_samples", sc.batteries)?;
        spinal.set_item("imu_frames", sc.imu_frames)?;
        spinal.set_item("servo_frames", sc.servo_frames)?;
        spinal.set_item("finish_step", sc.finish_step)?;
        spinal.set_item("finish_publish", sc.finish_publish)?;
        spinal.set_item("receive_then_kernel", sc.receive_then_kernel)?;
        spinal.set_item("receive_then_python", sc.receive_then_python)?;
        d.set_item("spinal_busy", spinal)?;
        d.set_item("fast_ns", self.counts.fast_ns.clone())?;
        d.set_item("python_ns", self.counts.python_ns.clone())?;
        d.set_item("physics_ns", self.counts.physics_ns)?;
        d.set_item("barriers_ns", self.counts.barriers_ns)?;
        Ok(d)
    }
}

/// The mask of part names (`set_touches`).
pub(crate) fn parts_mask(parts: &[String]) -> PyResult<u8> {
    let mut mask = 0;
    for p in parts {
        mask |= match p.as_str() {
            "plant" => PLANT,
            "bridge" => BRIDGE,
            "bank" => BANK,
            "spinal" => SPINAL,
            "leptrino" => LEPTRINO,
            other => {
                return Err(pyo3::exceptions::PyValueError::new_err(format!(
                    "unknown kernel part {other:?}"
                )))
            }
        };
    }
    Ok(mask)
}

fn elapsed_ns(t0: std::time::Instant) -> u64 {
    u64::try_from(t0.elapsed().as_nanos()).unwrap_or(u64::MAX)
}

impl LockstepKernel {
    fn check_index(&self, index: usize) -> PyResult<()> {
        if index >= self.ticks.len() {
            return Err(pyo3::exceptions::PyIndexError::new_err(format!(
                "LockstepKernel: node index {index} out of range"
            )));
        }
        Ok(())
    }
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<LockstepKernel>()?;
    Ok(())
}
