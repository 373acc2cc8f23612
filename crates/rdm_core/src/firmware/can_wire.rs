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

/// Default capacity of each delivery queue (frames waiting for the other side's tick).
pub const DEFAULT_QUEUE_CAPACITY: usize = 4096;
/// Default capacity of the capture log (frames waiting to be written).
pub const DEFAULT_LOG_CAPACITY: usize = 65536;

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
            let _ = write!(out, "({stamp:.6}) {channel} {:03X}#", f.frame.id);
            for b in f.frame.payload() {
                let _ = write!(out, "{b:02X}");
            }
            out.push_str(" R\n");
        }
        self.log.clear();
    }
}
