//! The Neuron bank's wire tick (`NeuronBankNode.tick` on a `CanWireLink`): the one call
//! `NeuronBank.tick_wire` makes (the bridge snapshot's present positions pushed when a frame
//! will read them, the Rust boards ticked, replies on the wire). The bank's counters (frames
//! sent per board, change counters) are the core's own: nothing to write back.

use pyo3::prelude::*;

use crate::can_master::CanWire;
use crate::neuron_bank::NeuronBank;

pub(crate) struct BankFast {
    bank: Py<NeuronBank>,
    wire: Py<CanWire>,
    /// The boards that sent in a tick (scratch).
    boards: Vec<usize>,
}

impl BankFast {
    pub(crate) fn new(bank: Py<NeuronBank>, wire: Py<CanWire>) -> Self {
        BankFast {
            bank,
            wire,
            boards: Vec::with_capacity(16),
        }
    }

    pub(crate) fn invalidate(&mut self) {}

    /// The wire tick is the bank's one form (`NeuronBank.tick_wire`): it always runs here.
    pub(crate) fn ready(&mut self, _py: Python<'_>) -> PyResult<bool> {
        Ok(true)
    }

    /// The tick at `now`; replies stamped `now` (the channel clock).
    pub(crate) fn tick(&mut self, py: Python<'_>, now: f64) -> PyResult<()> {
        let mut bank = self.bank.bind(py).borrow_mut();
        let mut wire = self.wire.bind(py).borrow_mut();
        bank.kernel_tick_wire(now, now, &mut wire.core, &mut self.boards)
    }

    pub(crate) fn flush(&mut self, _py: Python<'_>) -> PyResult<()> {
        Ok(())
    }
}
