//! The Spinal mirror's routine milliseconds (`SpinalMirror.tick` with no UART byte waiting,
//! inside the rosserial idle window, one steady CAN ms):
//!
//! * the idle ms: one Rust CAN master tick on the wire;
//! * the busy ms (docs/spinal.md): the battery sample, one control step
//!   (`SpinalStep.step` on the mirror's IMU sample, the duty list, the duty hand-over to the
//!   Rust master), the `imu` and `servo/states` publications (frames from the Rust builders,
//!   `ClientSession.send_frame`'s checks and counters), then the CAN ms; the frames go to a
//!   buffer written to the UART in one send at the next flush.
//!
//! Anything else (an event of the step, a frame the builders or the TX ring decline, a
//! non-finite battery sample, another publisher, a second control step) is decided before
//! any state changes (the Python tick runs) or, once the step ran, handed to the mirror's
//! `kernel_finish_*` continuation. The mirror's Python state is written back before Python
//! code runs.
//!
//! Files: `names` (the mirror's interned names), `plan` (the plan read from the mirror),
//! `ready` (whether a tick runs here), `tick` (the tick), `flush` (the write-back).

mod flush;
mod names;
mod plan;
mod ready;
mod tick;

use pyo3::prelude::*;
use pyo3::types::PyTuple;

use crate::can_master::{CanMaster, CanWire};
use crate::spinal_state::SpinalMirrorState;
use flush::Deferred;
use names::Names;
use plan::Plan;
use ready::Decision;

/// Busy-ms counts (the kernel's `stats()`).
#[derive(Clone, Copy, Default)]
pub(crate) struct BusyCounts {
    pub(crate) steps: u64,
    pub(crate) batteries: u64,
    pub(crate) imu_frames: u64,
    pub(crate) servo_frames: u64,
    pub(crate) finish_step: u64,
    pub(crate) finish_publish: u64,
    /// Ms with bytes to read: received in Python, the rest run here / in Python.
    pub(crate) receive_then_kernel: u64,
    pub(crate) receive_then_python: u64,
}

pub(crate) struct SpinalFast {
    node: Py<PyAny>,
    /// The mirror's clock and battery state (`SpinalMirror._state`), changed in place.
    state: Py<SpinalMirrorState>,
    names: Names,
    master: Py<CanMaster>,
    wire: Py<CanWire>,
    drain_at: usize,
    plan: Option<Plan>,
    loaded: bool,
    dirty: bool,
    decision: Decision,
    deferred: Deferred,
    /// Frames not yet written (`flush` writes them through the UART chain), and this tick's.
    tx: Vec<u8>,
    tick_tx: Vec<u8>,
    /// Per publishing tick in `tx`: (its time s, end of its bytes in `tx`), for the capture's
    /// time index (`TimedCaptureFile.write_marked`).
    tx_marks: Vec<(f64, usize)>,
    pub(crate) counts: BusyCounts,
}

/// What a tick did.
pub(crate) enum SpinalTick {
    /// The whole tick ran here.
    Done,
    /// The CAN tick left work for Python (`SpinalMirror.kernel_finish_wire_tick(now_ms)`).
    Finish(i64),
    /// The control step ran here, the rest is Python's
    /// (`SpinalMirror.kernel_finish_step(now_ms, tail)`).
    FinishStep(i64, bool),
    /// Everything up to the publications ran here, they are Python's
    /// (`SpinalMirror.kernel_finish_publish(now_ms)`).
    FinishPublish(i64),
}

impl SpinalFast {
    pub(crate) fn new(
        node: &Bound<'_, PyAny>,
        state: Py<SpinalMirrorState>,
        master: Py<CanMaster>,
        wire: Py<CanWire>,
        drain_at: usize,
    ) -> Self {
        let py = node.py();
        SpinalFast {
            node: node.clone().unbind(),
            state,
            names: Names::new(py),
            master,
            wire,
            drain_at,
            plan: None,
            loaded: false,
            dirty: false,
            decision: Decision::Idle,
            deferred: Deferred::default(),
            tx: Vec::with_capacity(8192),
            tick_tx: Vec::with_capacity(1024),
            tx_marks: Vec::with_capacity(64),
            counts: BusyCounts::default(),
        }
    }

    pub(crate) fn invalidate(&mut self) {
        self.loaded = false;
    }

    /// A ms this part cannot run from its plan (`ready` false), bytes to read or not:
    /// `SpinalMirror.kernel_receive_tick(now)` receives them in Python and runs the whole
    /// tick there (None), or hands back the plan for the rest of the ms (the caller loads it
    /// with `load_plan` once its `leave_python` is done; `ready` then judges the ms). The
    /// caller brackets the call as Python code (`enter_python` / `leave_python`).
    pub(crate) fn receive_tick<'py>(
        &mut self,
        py: Python<'py>,
        now: f64,
    ) -> PyResult<Option<Bound<'py, PyTuple>>> {
        let plan = self
            .node
            .bind(py)
            .call_method1(pyo3::intern!(py, "kernel_receive_tick"), (now,))?;
        if plan.is_none() {
            self.counts.receive_then_python += 1;
            return Ok(None);
        }
        Ok(Some(plan.cast_into::<PyTuple>()?))
    }

    /// The plan `receive_tick` handed back: read after the mirror's Python code ran, and
    /// nothing has run since.
    pub(crate) fn load_plan(&mut self, plan: Bound<'_, PyTuple>) -> PyResult<()> {
        self.load(Some(plan))
    }

    /// The rest of a `receive_tick` ms that `ready` declined (`kernel_receive_rest`).
    pub(crate) fn receive_rest(&mut self, py: Python<'_>, now: f64) -> PyResult<()> {
        self.counts.receive_then_python += 1;
        self.node
            .bind(py)
            .call_method1(pyo3::intern!(py, "kernel_receive_rest"), (now,))?;
        Ok(())
    }

    /// `SpinalMirror.kernel_finish_wire_tick(now_ms)` (after a flush of every part).
    pub(crate) fn finish(&self, py: Python<'_>, now_ms: i64) -> PyResult<()> {
        self.node
            .bind(py)
            .call_method1("kernel_finish_wire_tick", (now_ms,))?;
        Ok(())
    }

    /// `SpinalMirror.kernel_finish_step(now_ms, tail)` (after a flush of every part).
    pub(crate) fn finish_step(&self, py: Python<'_>, now_ms: i64, tail: bool) -> PyResult<()> {
        self.node
            .bind(py)
            .call_method1("kernel_finish_step", (now_ms, tail))?;
        Ok(())
    }

    /// `SpinalMirror.kernel_finish_publish(now_ms)` (after a flush of every part).
    pub(crate) fn finish_publish(&self, py: Python<'_>, now_ms: i64) -> PyResult<()> {
        self.node
            .bind(py)
            .call_method1("kernel_finish_publish", (now_ms,))?;
        Ok(())
    }
}
