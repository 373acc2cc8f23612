//! What the busy ms changed since the last flush, and the flush that writes it back to the
//! mirror (battery sample ms, control output, duties, publications, the UART bytes).

use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict, PyList};
use rdm_core::control::attitude::SpinalOutput;
use rdm_core::MAX_ROTORS;

use super::names::Names;
use super::plan::Chain;
use super::SpinalFast;
use crate::attitude::SpinalStepOutput;
use crate::kernel::attr::Name;

/// A duty list: values and length.
#[derive(Clone, Copy)]
pub(super) struct Duties {
    pub(super) values: [f64; MAX_ROTORS],
    pub(super) n: usize,
}

impl Duties {
    fn list<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        PyList::new(py, self.values.iter().take(self.n).copied())
    }
}

/// What the busy ms changed since the last flush.
#[derive(Default)]
pub(super) struct Deferred {
    /// The output of the last control step here (its `SpinalStepOutput` is made at flush).
    pub(super) output: Option<SpinalOutput>,
    /// The last duty list (`duties`), whether it is also the one handed over, and the last
    /// one handed over (`_duties_to_master`).
    pub(super) duties: Option<Duties>,
    pub(super) duties_handed: bool,
    pub(super) handed: Option<Duties>,
    /// The ms of the last battery sample here (`_last_pub["_battery_sample"]`).
    pub(super) battery_ms: Option<i64>,
    pub(super) imu_last: bool,
    pub(super) servo_last: bool,
    pub(super) frames: i64,
    pub(super) imu_frames: i64,
    pub(super) servo_frames: i64,
}

impl SpinalFast {
    /// Write the mirror's Python state back: what the busy ms changed (battery sample ms,
    /// control output, duties, publications, the UART bytes). The clock, CAN ms, control
    /// time and battery voltage (`SpinalMirrorState`), the CAN master's counters
    /// (`CanMaster.tx_count`, `pending_events`) and the control step count
    /// (`SpinalStep.steps`) are their Rust objects' own: nothing of them is written here.
    pub(crate) fn flush(&mut self, py: Python<'_>) -> PyResult<()> {
        if !self.dirty {
            return Ok(());
        }
        if let Some(p) = &self.plan {
            let node = self.node.bind(py);
            let n = &self.names;
            let d = std::mem::take(&mut self.deferred);
            let last_pub = if d.battery_ms.is_some() || d.imu_last || d.servo_last {
                Some(n.last_pub.get(node)?.cast_into::<PyDict>()?)
            } else {
                None
            };
            if let (Some(ms), Some(last)) = (d.battery_ms, &last_pub) {
                last.set_item(n.battery_sample.key(py), ms)?;
            }
            if let Some(out) = d.output {
                n.last_output
                    .set(node, Py::new(py, SpinalStepOutput { inner: out })?)?;
            }
            if let Some(duties) = &d.duties {
                let list = duties.list(py)?;
                n.duties.set(node, &list)?;
                if d.duties_handed {
                    n.duties_to_master.set(node, &list)?;
                } else if let Some(handed) = &d.handed {
                    n.duties_to_master.set(node, handed.list(py)?)?;
                }
            }
            if let (Some(b), Some(last)) = (&p.busy, &last_pub) {
                if d.imu_last {
                    last.set_item(n.imu.key(py), b.imu_last)?;
                }
                if d.servo_last {
                    last.set_item(n.servo_states.key(py), b.servo_last)?;
                }
            }
            if d.frames > 0 {
                let data = PyBytes::new(py, &self.tx);
                self.tx.clear();
                // `ready` publishes only with a chain to write through.
                let chain = p
                    .busy
                    .as_ref()
                    .and_then(|b| b.chain.as_ref())
                    .ok_or_else(|| {
                        pyo3::exceptions::PyRuntimeError::new_err(
                            "kernel: Spinal frames without a UART chain",
                        )
                    })?;
                Self::commit_tx(n, node, chain, &data, &d, &self.tx_marks)?;
            }
        }
        self.tx.clear();
        self.tx_marks.clear();
        self.deferred = Deferred::default();
        self.dirty = false;
        Ok(())
    }

    /// mirror's counters, then `UartPump.send(data)` of a whole write through the chain
    /// (`_write_chain`: the cut line counts the bytes lost; else the peer's inbox and the
    /// capture tap take them) and `bytes_out` (the plan's `writes_whole` held since).
    fn commit_tx(
        n: &Names,
        node: &Bound<'_, PyAny>,
        chain: &Chain,
        data: &Bound<'_, PyBytes>,
        d: &Deferred,
        marks: &[(f64, usize)],
    ) -> PyResult<()> {
        let py = node.py();
        let add = |obj: &Bound<'_, PyAny>, key: &Name, k: i64| -> PyResult<()> {
            let key = key.key(py);
            let v: i64 = obj.get_item(key)?.extract()?;
            obj.set_item(key, v + k)
        };
        add(
            &n.counts.get(&n.session.get(node)?)?,
            &n.tx_frames,
            d.frames,
        )?;
        let published = n.published.get(&n.counters.get(node)?)?;
        if d.imu_frames > 0 {
            add(&published, &n.imu, d.imu_frames)?;
        }
        if d.servo_frames > 0 {
            add(&published, &n.servo_states, d.servo_frames)?;
        }
        let len = i64::try_from(data.as_bytes().len()).unwrap_or(i64::MAX);
        let cut = match &chain.droppable {
            Some(link) => n.dropped.truthy(link.bind(py))?,
            None => false,
        };
        if let (true, Some(link)) = (cut, &chain.droppable) {
            let link = link.bind(py);
            n.bytes_lost.set(link, n.bytes_lost.i64(link)? + len)?;
        } else {
            let peer = n.peer.get(chain.end.bind(py))?;
            n.inbox
                .get(&peer)?
                .call_method1(n.extend.key(py), (data,))?;
            if let Some(tap) = &chain.tapped {
                let tap = tap.bind(py);
                n.tx_bytes.set(tap, n.tx_bytes.i64(tap)? + len)?;
                let file = n.tx_file.get(tap)?;
                if !file.is_none() {
                    // A time-indexed capture takes each tick's bytes at that tick's time.
                    match file.getattr(n.write_marked.key(py)) {
                        Ok(write_marked) => {
                            write_marked.call1((data, PyList::new(py, marks)?))?;
                        }
                        Err(_) => {
                            file.call_method1(n.write.key(py), (data,))?;
                        }
                    }
                }
            }
        }
        let uart = n.uart.get(node)?;
        n.bytes_out.set(&uart, n.bytes_out.i64(&uart)? + len)
    }
}
