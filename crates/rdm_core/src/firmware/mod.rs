//! Mirrors of the JSK board firmware that sit on the simulated CAN bus.
//!
//! The Neuron mirror (`neuron_*`) follows the Python reference `rdm.nodes.neuron_mirror`
//! frame for frame: same decoding (and error reasons), same replies, same byte order, so a
//! simulated run writes the same CAN log with either implementation.

pub mod bank_bridge;
pub mod can_master;
pub mod can_wire;
pub mod neuron_bank;
pub mod neuron_board;
pub mod neuron_frame;
pub mod neuron_servo;
pub mod neuron_tx;
pub mod rosserial_frame;
pub mod spinal_frame;
pub mod spinal_state;
