//! The Neuron bank's wire tick (`NeuronBankNode.tick` on a `CanWireLink` with the bridge
//! attached): present positions pushed when a frame will read them, the Rust boards ticked,
//! replies on the wire. The bank's counters (frames sent per board, change counters) are
//! the core's own: nothing to write back.

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

    /// The tick runs here once the plant bridge's coupling is attached (a position push is
    /// then the core's own).
    pub(crate) fn ready(&mut self, py: Python<'_>) -> PyResult<bool> {
        Ok(self.bank.bind(py).borrow().is_bridged())
    }

    /// The tick at `now` (requires `ready`); replies stamped `now` (the channel clock).
    pub(crate) fn tick(&mut self, py: Python<'_>, now: f64) -> PyResult<()> {
        let mut bank = self.bank.bind(py).borrow_mut();
        let mut wire = self.wire.bind(py).borrow_mut();
        let pending = wire.core.for_neurons().iter().any(|f| f.id >= 0x100);
        if pending || bank.kernel_sent_frames_heard() {
            bank.kernel_push_positions()?;
        }
        bank.kernel_tick_wire(now, now, &mut wire.core, &mut self.boards)
    }

    pub(crate) fn flush(&mut self, _py: Python<'_>) -> PyResult<()> {
        Ok(())
    }
}
