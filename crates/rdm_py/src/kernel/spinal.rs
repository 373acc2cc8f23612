//! The Spinal mirror's idle millisecond (`SpinalMirror.tick` with no UART byte, no control
//! step, battery sample or publisher due and a steady CAN ms): one Rust CAN master tick on
//! the wire. The mirror's Python state is written back before Python code runs.

use pyo3::prelude::*;
use pyo3::types::PyTuple;

use super::attr::Name;
use crate::can_master::{CanMaster, CanWire};

struct Names {
    now_ms: Name,
    now_s: Name,
    can_ms: Name,
    master: Name,
    tx_count: Name,
    pending_events: Name,
}

/// Plan of `SpinalMirror.kernel_plan()`: the window in which a tick is only the CAN ms.
struct Plan {
    now_ms: i64,
    now_s: f64,
    idle_lo: i64,
    idle_hi: i64,
    battery_due_ms: i64,
    next_control: f64,
    can_ms: i64,
    next_pub_ms: i64,
}

pub(crate) struct SpinalFast {
    node: Py<PyAny>,
    names: Names,
    master: Py<CanMaster>,
    wire: Py<CanWire>,
    drain_at: usize,
    plan: Option<Plan>,
    loaded: bool,
    tx_delta: i64,
    /// A steady CAN tick ran since the last flush (the master's pending events are 0).
    steady: bool,
    dirty: bool,
}

/// What a tick did.
pub(crate) enum SpinalTick {
    /// The whole tick ran here.
    Done,
    /// The CAN tick left work for Python (`SpinalMirror.kernel_finish_wire_tick(now_ms)`).
    Finish(i64),
}

impl SpinalFast {
    pub(crate) fn new(
        node: &Bound<'_, PyAny>,
        master: Py<CanMaster>,
        wire: Py<CanWire>,
        drain_at: usize,
    ) -> Self {
        let py = node.py();
        SpinalFast {
            node: node.clone().unbind(),
            names: Names {
                now_ms: Name::new(py, "now_ms"),
                now_s: Name::new(py, "_now_s"),
                can_ms: Name::new(py, "_can_ms"),
                master: Name::new(py, "master"),
                tx_count: Name::new(py, "tx_count"),
                pending_events: Name::new(py, "_pending_events"),
            },
            master,
            wire,
            drain_at,
            plan: None,
            loaded: false,
            tx_delta: 0,
            steady: false,
            dirty: false,
        }
    }

    pub(crate) fn invalidate(&mut self) {
        self.loaded = false;
    }

    fn ensure_loaded(&mut self, py: Python<'_>) -> PyResult<()> {
        if self.loaded {
            return Ok(());
        }
        let plan = self.node.bind(py).call_method0("kernel_plan")?;
        self.plan = if plan.is_none() {
            None
        } else {
            let t = plan.cast::<PyTuple>()?;
            Some(Plan {
                now_ms: t.get_item(0)?.extract()?,
                now_s: t.get_item(1)?.extract()?,
                idle_lo: t.get_item(2)?.extract()?,
                idle_hi: t.get_item(3)?.extract()?,
                battery_due_ms: t.get_item(4)?.extract()?,
                next_control: t.get_item(5)?.extract()?,
                can_ms: t.get_item(6)?.extract()?,
                next_pub_ms: t.get_item(7)?.extract()?,
            })
        };
        self.loaded = true;
        Ok(())
    }

    /// `to_ms(now)` as the mirror computes it.
    fn to_ms(now: f64) -> i64 {
        (now * 1000.0 + 1e-6).floor() as i64
    }

    /// Whether the tick at `now` is an idle ms this path runs.
    pub(crate) fn ready(&mut self, py: Python<'_>, now: f64) -> PyResult<bool> {
        self.ensure_loaded(py)?;
        let Some(p) = &self.plan else {
            return Ok(false);
        };
        let m = Self::to_ms(now);
        let now_s = if now > p.now_s { now } else { p.now_s };
        Ok(m >= p.now_ms
            && p.idle_lo <= m
            && m < p.idle_hi
            && m < p.battery_due_ms
            && now_s < p.next_control - 1e-9
            && m == p.can_ms + 1
            && m < p.next_pub_ms)
    }

    /// The idle tick at `now` (requires `ready`).
    pub(crate) fn tick(&mut self, py: Python<'_>, now: f64) -> PyResult<SpinalTick> {
        let m = Self::to_ms(now);
        let Some(p) = &mut self.plan else {
            return Err(pyo3::exceptions::PyRuntimeError::new_err(
                "kernel: Spinal tick without a plan",
            ));
        };
        if now > p.now_s {
            p.now_s = now;
        }
        p.now_ms = m;
        p.can_ms = m;
        self.dirty = true;
        let sent = {
            let wire = self.wire.bind(py);
            self.master
                .bind(py)
                .borrow_mut()
                .tick_wire_steady(m, now, wire, self.drain_at)
        };
        if sent >= 0 {
            self.tx_delta += sent;
            self.steady = true;
            Ok(SpinalTick::Done)
        } else {
            Ok(SpinalTick::Finish(m))
        }
    }

    /// Write the mirror's clock and CAN ms, and the master's counters of the steady CAN
    /// ms, back (`now_ms`, `_now_s`, `_can_ms`; `tx_count`, `_pending_events` = 0).
    pub(crate) fn flush(&mut self, py: Python<'_>) -> PyResult<()> {
        if !self.dirty {
            return Ok(());
        }
        if let Some(p) = &self.plan {
            let node = self.node.bind(py);
            let n = &self.names;
            n.now_ms.set(node, p.now_ms)?;
            n.now_s.set(node, p.now_s)?;
            n.can_ms.set(node, p.can_ms)?;
            if self.steady {
                let master = n.master.get(node)?;
                let tx = n.tx_count.i64(&master)?;
                n.tx_count.set(&master, tx + self.tx_delta)?;
                n.pending_events.set(&master, 0)?;
            }
        }
        self.tx_delta = 0;
        self.steady = false;
        self.dirty = false;
        Ok(())
    }

    /// `SpinalMirror.kernel_finish_wire_tick(now_ms)` (after a flush of every part).
    pub(crate) fn finish(&self, py: Python<'_>, now_ms: i64) -> PyResult<()> {
        self.node
            .bind(py)
            .call_method1("kernel_finish_wire_tick", (now_ms,))?;
        Ok(())
    }
}
