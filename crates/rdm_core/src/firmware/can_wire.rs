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
//!
//! Fault hooks (the fault campaign; off by default, and then no frame and no byte differs):
//! - frame loss ([`CanWire::set_loss`]): each frame, either direction, is lost with a
//!   probability (a seeded xorshift64* stream): damaged on the wire, it reaches nobody and is
//!   not in the capture; every controller on the bus sees the error frame, counted in
//!   `error_frames` (what Spinal's CAN peripheral reports). ASSUMPTION: no retransmission
//!   (the firmware enables it; a lost frame models one that is not repeated in time) and the
//!   error counters never reach error-passive;
//! - bus-off ([`CanWire::bus_off`]): the bus disturbed for a while; the controllers go
//!   bus-off and rejoin after 128 occurrences of 11 recessive bits once the disturbance ends
//!   ([`BUS_OFF_RECOVERY_S`] at 1 Mbit/s, the bxCAN's automatic recovery); until then every
//!   frame is lost (`bus_off_lost`) and `bus_off` counts the episode.

use std::fmt::Write;

use super::neuron_frame::CanFrame;
use super::neuron_tx::RxFrame;
use crate::sim::fixed_decimals::push_fixed6;

/// Default capacity of each delivery queue (frames waiting for the other side's tick).
pub const DEFAULT_QUEUE_CAPACITY: usize = 4096;
/// Default capacity of the capture log (frames waiting to be written).
pub const DEFAULT_LOG_CAPACITY: usize = 65536;

/// Bit rate of the Neuron bus, bit/s (jsk-wire-protocols.md sec. 2.1).
pub const BIT_RATE: f64 = 1_000_000.0;
/// Bus-off recovery: 128 occurrences of 11 consecutive recessive bits, s.
pub const BUS_OFF_RECOVERY_S: f64 = 128.0 * 11.0 / BIT_RATE;

/// Why a fault hook was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WireFaultError {
    /// A loss probability outside [0, 1] or not finite.
    Probability,
    /// A bus-off start or duration not finite, or a negative duration.
    Duration,
}

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
    loss_probability: f64,
    rng: u64,
    silent_from: f64,
    silent_until: f64,
    /// Frames lost to the frame-loss fault.
    pub lost: u64,
    /// Error frames on the bus (one per lost frame), as Spinal's CAN peripheral counts them.
    pub error_frames: u64,
    /// Bus-off episodes.
    pub bus_off: u64,
    /// Frames lost while the bus was off.
    pub bus_off_lost: u64,
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
            loss_probability: 0.0,
            rng: 1,
            silent_from: f64::INFINITY,
            silent_until: f64::NEG_INFINITY,
            lost: 0,
            error_frames: 0,
            bus_off: 0,
            bus_off_lost: 0,
        }
    }

    /// Fault hook: each later frame is lost with probability `p` (0: off), drawn from a
    /// stream seeded with `seed`.
    pub fn set_loss(&mut self, p: f64, seed: u64) -> Result<(), WireFaultError> {
        if !(p.is_finite() && (0.0..=1.0).contains(&p)) {
            return Err(WireFaultError::Probability);
        }
        self.loss_probability = p;
        // splitmix64 of the seed: a non-zero xorshift state for every seed
        let mut z = seed.wrapping_add(0x9E37_79B9_7F4A_7C15);
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        self.rng = (z ^ (z >> 31)) | 1;
        Ok(())
    }

    /// Fault hook: the bus is disturbed from channel time `start` for `disturbed_s`; the
    /// controllers go bus-off and rejoin [`BUS_OFF_RECOVERY_S`] after the disturbance ends.
    /// Frames sent from `start` until then are lost.
    pub fn bus_off(&mut self, start: f64, disturbed_s: f64) -> Result<(), WireFaultError> {
        if !(start.is_finite() && disturbed_s.is_finite() && disturbed_s >= 0.0) {
            return Err(WireFaultError::Duration);
        }
        self.bus_off += 1;
        let end = start + disturbed_s + BUS_OFF_RECOVERY_S;
        if start > self.silent_until {
            self.silent_from = start; // a later episode: the earlier one is over
        } else {
            self.silent_from = self.silent_from.min(start);
        }
        self.silent_until = self.silent_until.max(end);
        Ok(())
    }

    /// The channel time at which the bus carries frames again (-inf: never off).
    pub fn silent_until(&self) -> f64 {
        self.silent_until
    }

    /// A uniform draw in [0, 1) (xorshift64*).
    fn draw(&mut self) -> f64 {
        let mut x = self.rng;
        x ^= x >> 12;
        x ^= x << 25;
        x ^= x >> 27;
        self.rng = x;
        (x.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Whether a frame sent at `stamp` is lost (counted); false with the hooks off.
    fn lose(&mut self, stamp: f64) -> bool {
        if self.silent_from <= stamp && stamp < self.silent_until {
            self.bus_off_lost += 1;
            return true;
        }
        if self.loss_probability > 0.0 && self.draw() < self.loss_probability {
            self.lost += 1;
            self.error_frames += 1;
            return true;
        }
        false
    }

    /// Send one frame at channel time `stamp`: logged, then queued for the other side (unless
    /// a fault hook loses it).
    pub fn send(&mut self, from: Sender, stamp: f64, frame: CanFrame) {
        if self.lose(stamp) {
            return;
        }
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

    fn frame(k: u8) -> CanFrame {
        CanFrame {
            id: 0x200 | u16::from(k & 0xF),
            len: 1,
            data: [k, 0, 0, 0, 0, 0, 0, 0],
        }
    }

    #[test]
    fn lost_frames_follow_their_probability_and_reach_nobody() {
        let (n, p) = (100_000u64, 0.05);
        let mut wire = CanWire::new(8, 8, true);
        wire.set_loss(p, 7).expect("p");
        let mut delivered = 0u64;
        let mut out = Vec::new();
        for k in 0..n {
            wire.send(Sender::Master, k as f64 * 1e-3, frame(k as u8));
            wire.take_for_neurons(&mut out);
            delivered += out.len() as u64;
            wire.log.clear();
        }
        let sigma = (n as f64 * p * (1.0 - p)).sqrt();
        assert!(
            (wire.lost as f64 - n as f64 * p).abs() < 5.0 * sigma,
            "{}",
            wire.lost
        );
        assert_eq!(wire.lost + delivered, n);
        assert_eq!(wire.frames, delivered);
        assert_eq!(wire.error_frames, wire.lost);
        assert!(wire.set_loss(1.5, 1).is_err() && wire.set_loss(f64::NAN, 1).is_err());
    }

    #[test]
    fn bus_off_silences_the_bus_until_the_recovery_bits() {
        let mut wire = CanWire::new(64, 64, true);
        wire.bus_off(1.0, 0.05).expect("bus off");
        let end = 1.05 + 128.0 * 11.0 / 1e6; // 1.051408 s
        let stamps = [0.999, 1.0, 1.03, end - 1e-6, end, end + 1e-3];
        for (k, t) in stamps.iter().enumerate() {
            wire.send(Sender::Neurons, *t, frame(k as u8));
        }
        let mut out = Vec::new();
        wire.take_for_master(&mut out);
        let kept: Vec<u8> = out.iter().map(|f| f.data[0]).collect();
        assert_eq!(kept, vec![0, 4, 5]); // before the fault, and from the recovery on
        assert_eq!((wire.bus_off, wire.bus_off_lost, wire.lost), (1, 3, 0));
        assert!(wire.bus_off(1.0, -1.0).is_err());
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
