//! The Neuron CAN bus between the Rust CAN master (Spinal) and the Rust Neuron bank, without
//! python-can in between: two bounded delivery queues and a bounded capture log.
//!
//! Semantics of the in-process python-can channel it replaces, when the master and the bank
//! are its only endpoints: a frame one side sends is delivered to the other side's queue in
//! send order and read at that side's next tick (nobody hears itself); every frame is
//! stamped with the channel clock at send time and seen by the candump capture in send
//! order. The log formats exactly as python-can's `CanutilsLogWriter` (`candump -L`): the
//! first frame's stamp is the floor of later stamps. Storage is fixed at setup: sending and
//! delivering allocate nothing; a frame beyond a full queue or log is dropped and counted.

use std::fmt::Write;

use super::neuron_frame::CanFrame;
use super::neuron_tx::RxFrame;
use crate::sim::fixed_decimals::push_fixed6;

/// Default capacity of each delivery queue (frames waiting for the other side's tick).
pub const DEFAULT_QUEUE_CAPACITY: usize = 4096;
/// Default capacity of the capture log (frames waiting to be written).
pub const DEFAULT_LOG_CAPACITY: usize = 65536;

/// Upper-case hex digits (`{:X}`).
const HEX: &[u8; 16] = b"0123456789ABCDEF";

/// `{:03X}` of `id`: three digits for an 11-bit id, the formatter for anything wider.
fn push_hex3(out: &mut String, id: u32) {
    if id > 0xFFF {
        let _ = write!(out, "{id:03X}");
        return;
    }
    for shift in [8, 4, 0] {
        out.push(char::from(HEX[((id >> shift) & 0xF) as usize]));
    }
}

/// One captured frame: channel-clock stamp (s) and the frame.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LoggedFrame {
    /// Channel clock at send time.
    pub stamp: f64,
    /// The frame (classic, standard id).
    pub frame: CanFrame,
}

/// Which endpoint sent a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Sender {
    /// Spinal's CAN master (delivered to the Neurons).
    Master,
    /// The Neuron bank (delivered to the master).
    Neurons,
}

/// The two-endpoint bus with its capture log.
#[derive(Debug, Clone)]
pub struct CanWire {
    to_neurons: Vec<RxFrame>,
    to_master: Vec<RxFrame>,
    log: Vec<LoggedFrame>,
    queue_capacity: usize,
    log_capacity: usize,
    logging: bool,
    log_floor: Option<f64>,
    /// Frames sent on the wire (both directions).
    pub frames: u64,
    /// Frames dropped because a delivery queue was full.
    pub queue_dropped: u64,
    /// Frames missing from the log because it was full.
    pub log_dropped: u64,
}

impl CanWire {
    /// A wire with the given queue and log capacities (allocated now); `logging` false keeps
    /// no capture log.
    pub fn new(queue_capacity: usize, log_capacity: usize, logging: bool) -> CanWire {
        CanWire {
            to_neurons: Vec::with_capacity(queue_capacity),
            to_master: Vec::with_capacity(queue_capacity),
            log: Vec::with_capacity(if logging { log_capacity } else { 0 }),
            queue_capacity,
            log_capacity,
            logging,
            log_floor: None,
            frames: 0,
            queue_dropped: 0,
            log_dropped: 0,
        }
    }

    /// Send one frame at channel time `stamp`: logged, then queued for the other side.
    pub fn send(&mut self, from: Sender, stamp: f64, frame: CanFrame) {
        self.frames += 1;
        if self.logging {
            if self.log.len() < self.log_capacity {
                self.log.push(LoggedFrame { stamp, frame });
            } else {
                self.log_dropped += 1;
            }
        }
        let queue = match from {
            Sender::Master => &mut self.to_neurons,
            Sender::Neurons => &mut self.to_master,
        };
        if queue.len() < self.queue_capacity {
            queue.push(RxFrame::from_sent(&frame));
        } else {
            self.queue_dropped += 1;
        }
    }

    /// Frames waiting for the Neurons' next tick, in send order.
    pub fn for_neurons(&self) -> &[RxFrame] {
        &self.to_neurons
    }

    /// Frames waiting for the master's next tick, in send order.
    pub fn for_master(&self) -> &[RxFrame] {
        &self.to_master
    }

    /// The Neurons read their queue (after a tick).
    pub fn clear_for_neurons(&mut self) {
        self.to_neurons.clear();
    }

    /// The master read its queue (after a tick).
    pub fn clear_for_master(&mut self) {
        self.to_master.clear();
    }

    /// Move the pending frames for the Neurons into `out` (which keeps its capacity).
    pub fn take_for_neurons(&mut self, out: &mut Vec<RxFrame>) {
        out.clear();
        out.extend_from_slice(&self.to_neurons);
        self.to_neurons.clear();
    }

    /// Move the pending frames for the master into `out` (which keeps its capacity).
    pub fn take_for_master(&mut self, out: &mut Vec<RxFrame>) {
        out.clear();
        out.extend_from_slice(&self.to_master);
        self.to_master.clear();
    }

    /// Frames in the capture log.
    pub fn log_len(&self) -> usize {
        self.log.len()
    }

    /// Append the logged frames to `out` as `candump -L` lines on `channel` (python-can's
    /// `CanutilsLogWriter` format; every frame a received classic standard-id data frame)
    /// and empty the log.
    pub fn drain_log(&mut self, channel: &str, out: &mut String) {
        for f in &self.log {
            let floor = *self.log_floor.get_or_insert(f.stamp);
            let stamp = if f.stamp < floor { floor } else { f.stamp };
            out.push('(');
            push_fixed6(out, stamp); // `{stamp:.6}`, the same text
            out.push_str(") ");
            out.push_str(channel);
            out.push(' ');
            // `{:03X}#` and `{:02X}` per byte, without the formatting machinery (the
            // lines are most of a run's capture work); standard ids are 11 bits
            push_hex3(out, u32::from(f.frame.id));
            out.push('#');
            for &b in f.frame.payload() {
                out.push(char::from(HEX[usize::from(b >> 4)]));
                out.push(char::from(HEX[usize::from(b & 0x0F)]));
            }
            out.push_str(" R\n");
        }
        self.log.clear();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The lines as the formatter writes them (the form before the hand-written hex).
    fn formatted(stamp: f64, channel: &str, frame: &CanFrame) -> String {
        let mut s = format!("({stamp:.6}) {channel} {:03X}#", frame.id);
        for b in frame.payload() {
            s.push_str(&format!("{b:02X}"));
        }
        s + " R\n"
    }

    #[test]
    fn drained_lines_equal_the_formatters() {
        let mut wire = CanWire::new(8, 4096, true);
        let mut expect = String::new();
        let mut seed = 0x2545_f491_u32;
        let mut next = || {
            seed ^= seed << 13;
            seed ^= seed >> 17;
            seed ^= seed << 5;
            seed
        };
        for k in 0..2048u32 {
            let id =
                [0, 0x7FF, 0xFFF, 0x1000, 0xFFFF][k as usize % 5] as u16 ^ (next() as u16 & 0x7);
            let len = (next() % 9) as u8;
            let mut data = [0u8; 8];
            for b in data.iter_mut().take(len as usize) {
                *b = next() as u8;
            }
            let frame = CanFrame { id, len, data };
            let stamp = f64::from(k) * 0.000_5 + 1.0 / 3.0;
            expect.push_str(&formatted(stamp, "vcan0", &frame));
            wire.send(Sender::Master, stamp, frame);
            wire.take_for_neurons(&mut Vec::new());
        }
        let mut out = String::new();
        wire.drain_log("vcan0", &mut out);
        assert_eq!(out, expect);
        assert_eq!(wire.log_len(), 0);
    }
}
