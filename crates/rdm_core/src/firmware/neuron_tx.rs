//! The frames a bank of Neurons transmits in one tick, in send order, in a queue whose
//! capacity is fixed at setup (no allocation per tick).

use super::neuron_frame::CanFrame;

/// Frame flags of a received frame (python-can `Message` attributes).
pub const FLAG_EXTENDED: u8 = 1;
/// Remote (RTR) frame.
pub const FLAG_REMOTE: u8 = 2;
/// Error frame.
pub const FLAG_ERROR: u8 = 4;
/// CAN FD frame.
pub const FLAG_FD: u8 = 8;

/// One frame as a Neuron receives it from the bus.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct RxFrame {
    /// Arbitration id (11 or 29 bits).
    pub id: u32,
    /// `FLAG_*` bits.
    pub flags: u8,
    /// Payload length; may exceed 8 (FD or malformed), only the first 8 bytes are kept.
    pub len: usize,
    /// First 8 payload bytes.
    pub data: [u8; 8],
}

impl RxFrame {
    /// A frame from its id, flags and payload.
    pub fn new(id: u32, flags: u8, payload: &[u8]) -> RxFrame {
        let mut data = [0u8; 8];
        for (d, p) in data.iter_mut().zip(payload.iter()) {
            *d = *p;
        }
        RxFrame {
            id,
            flags,
            len: payload.len(),
            data,
        }
    }

    /// A frame another Neuron sent on the same bus.
    pub fn from_sent(frame: &CanFrame) -> RxFrame {
        RxFrame {
            id: frame.id as u32,
            flags: 0,
            len: frame.len as usize,
            data: frame.data,
        }
    }

    /// Payload bytes kept (at most 8); `len` tells the real length.
    pub fn kept(&self) -> &[u8] {
        self.data.get(..self.len.min(8)).unwrap_or(&self.data)
    }
}

/// One transmitted frame and the index (in the bank) of the board that sent it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct TxEntry {
    /// Board index in the bank.
    pub board: usize,
    /// The frame.
    pub frame: CanFrame,
}

/// Send queue of fixed capacity.
#[derive(Debug, Clone)]
pub struct TxQueue {
    frames: Vec<TxEntry>,
    capacity: usize,
}

impl TxQueue {
    /// A queue holding up to `capacity` frames (allocated now, never grown).
    pub fn with_capacity(capacity: usize) -> TxQueue {
        TxQueue {
            frames: Vec::with_capacity(capacity),
            capacity,
        }
    }

    /// Append a frame; false (frame dropped) when the queue is full.
    pub fn push(&mut self, board: usize, frame: CanFrame) -> bool {
        if self.frames.len() >= self.capacity {
            return false;
        }
        self.frames.push(TxEntry { board, frame });
        true
    }

    /// Frames queued, in send order.
    pub fn frames(&self) -> &[TxEntry] {
        &self.frames
    }

    /// Number of frames queued.
    pub fn len(&self) -> usize {
        self.frames.len()
    }

    /// True when nothing is queued.
    pub fn is_empty(&self) -> bool {
        self.frames.is_empty()
    }

    /// The frame at `k`, if any.
    pub fn get(&self, k: usize) -> Option<TxEntry> {
        self.frames.get(k).copied()
    }

    /// Empty the queue (capacity kept).
    pub fn clear(&mut self) {
        self.frames.clear();
    }

    /// Replace the contents by `other`'s (within capacity; extra frames are dropped).
    pub fn copy_from(&mut self, other: &TxQueue) {
        self.frames.clear();
        let n = other.frames.len().min(self.capacity);
        if let Some(src) = other.frames.get(..n) {
            self.frames.extend_from_slice(src);
        }
    }
}
