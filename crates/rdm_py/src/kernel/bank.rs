//! The Neuron bank's wire tick (`NeuronBankNode.tick` on a `CanWireLink` with the bridge
//! attached): present positions pushed when a frame will read them, the Rust boards ticked,
//! replies on the wire; the boards' Python counters written back before Python code runs.

use pyo3::prelude::*;
use pyo3::types::PyList;

use super::attr::Name;
use crate::can_master::CanWire;
use crate::neuron_bank::NeuronBank;

pub(crate) struct BankFast {
    node: Py<PyAny>,
    /// Returns the plan tuple, or None while the bank has no Rust tick
    /// (`rdm.nodes.lockstep_kernel`).
    plan_of: Py<PyAny>,
    /// The node's board views (`NeuronBankNode.boards`).
    boards_py: Vec<Py<PyAny>>,
    tx_count: Name,
    changes: Name,
    last_changes_name: Name,
    bank: Py<NeuronBank>,
    wire: Py<CanWire>,
    loaded: bool,
    ok: bool,
    /// Replies sent per board since the last flush.
    tx: Vec<i64>,
    /// The change counters the node last saw (`_last_changes`; empty: None).
    last_changes: Vec<u64>,
    changes_dirty: bool,
    dirty: bool,
    boards: Vec<usize>,
}

impl BankFast {
    pub(crate) fn new(
        node: &Bound<'_, PyAny>,
        bank: Py<NeuronBank>,
        wire: Py<CanWire>,
        boards_py: Vec<Py<PyAny>>,
        plan_of: Py<PyAny>,
    ) -> PyResult<Self> {
        let py = node.py();
        let n_boards = boards_py.len();
        if bank.bind(py).borrow().board_count() != n_boards {
            return Err(pyo3::exceptions::PyValueError::new_err(
                "attach_bank: boards differs from the bank's board count",
            ));
        }
        Ok(BankFast {
            node: node.clone().unbind(),
            plan_of,
            boards_py,
            tx_count: Name::new(py, "tx_count"),
            changes: Name::new(py, "changes"),
            last_changes_name: Name::new(py, "_last_changes"),
            bank,
            wire,
            loaded: false,
            ok: false,
            tx: vec![0; n_boards],
            last_changes: Vec::with_capacity(n_boards),
            changes_dirty: false,
            dirty: false,
            boards: Vec::with_capacity(16),
        })
    }

    pub(crate) fn invalidate(&mut self) {
        self.loaded = false;
    }

    fn ensure_loaded(&mut self, py: Python<'_>) -> PyResult<()> {
        if self.loaded {
            return Ok(());
        }
        let plan = self.plan_of.bind(py).call0()?;
        self.ok = !plan.is_none();
        if self.ok {
            let t = plan.cast_into::<pyo3::types::PyTuple>()?;
            let last = t.get_item(0)?;
            self.last_changes.clear();
            if !last.is_none() {
                self.last_changes = last.extract()?;
            }
        }
        self.loaded = true;
        Ok(())
    }

    pub(crate) fn ready(&mut self, py: Python<'_>) -> PyResult<bool> {
        self.ensure_loaded(py)?;
        Ok(self.ok)
    }

    /// The tick at `now` (requires `ready`); replies stamped `now` (the channel clock).
    pub(crate) fn tick(&mut self, py: Python<'_>, now: f64) -> PyResult<()> {
        let mut bank = self.bank.bind(py).borrow_mut();
        let mut wire = self.wire.bind(py).borrow_mut();
        let pending = wire.core.for_neurons().iter().any(|f| f.id >= 0x100);
        if pending || bank.kernel_sent_frames_heard() {
            bank.kernel_push_positions()?;
        }
        bank.kernel_tick_wire(now, now, &mut wire.core, &mut self.boards)?;
        for &b in &self.boards {
            if let Some(c) = self.tx.get_mut(b) {
                *c += 1;
            }
        }
        if !bank.kernel_refresh_changes(&mut self.last_changes) {
            self.changes_dirty = true;
        }
        self.dirty = true;
        Ok(())
    }

    /// Write the boards' counters back: each board's `tx_count`, and when they moved the
    /// change counters (`_last_changes`, each board's `changes[0]`), as
    /// `NeuronBankNode.tick` / `_refresh_changes` leave them.
    pub(crate) fn flush(&mut self, py: Python<'_>) -> PyResult<()> {
        if !self.dirty {
            return Ok(());
        }
        for (board, n) in self.boards_py.iter().zip(self.tx.iter_mut()) {
            if *n != 0 {
                let b = board.bind(py);
                let c = self.tx_count.i64(b)?;
                self.tx_count.set(b, c + *n)?;
                *n = 0;
            }
        }
        if self.changes_dirty {
            self.last_changes_name
                .set(self.node.bind(py), PyList::new(py, &self.last_changes)?)?;
            for (board, c) in self.boards_py.iter().zip(&self.last_changes) {
                self.changes.get(board.bind(py))?.set_item(0, *c)?;
            }
        }
        self.changes_dirty = false;
        self.dirty = false;
        Ok(())
    }
}
