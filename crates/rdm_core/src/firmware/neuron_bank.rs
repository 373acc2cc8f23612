//! Every Neuron of one CAN bus, ticked in one call: the frames pending on the bus go in,
//! the frames the boards send come out (board order, then send order), outputs are read from
//! the boards. Equivalent to one reference `NeuronMirror` per board, each with its own handle
//! on the shared bus, ticked in bank order at the same instant: board k also hears what the
//! boards after it sent in the previous tick (before the bus frames) and what the boards
//! before it sent in this tick (after them), as separate handles on one bus would.

use super::neuron_board::{BoardError, BoardSettings, NeuronBoard};
use super::neuron_frame::BROADCAST_ID;
use super::neuron_tx::{RxFrame, TxEntry, TxQueue};

/// Default send-queue capacity (frames per tick); a board-config burst to 14 boards with
/// four servos each is 14 x 13 = 182 frames.
pub const DEFAULT_TX_CAPACITY: usize = 4096;

/// Why a bank call was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BankError {
    /// A board could not be built (bank index, reason).
    Board(usize, BoardError),
    /// No boards, or more than 14.
    BoardCount,
    /// Two boards with the same slave id at setup.
    DuplicateSlave(u8),
    /// `now` is not finite.
    NonFiniteTime,
    /// Board index out of range.
    BoardIndex(usize),
    /// Servo index out of range for the board.
    ServoIndex(usize, usize),
    /// A present position is not finite (board, servo).
    NonFinitePosition(usize, usize),
    /// IMU sensor index not 0..2.
    Sensor(usize),
}

/// Frames a board handed to its bus: sent whole, and refused by the bus.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct TxCount {
    pub sent: u64,
    pub errors: u64,
}

/// The Neurons of one bus.
#[derive(Debug, Clone)]
pub struct NeuronBank {
    boards: Vec<NeuronBoard>,
    tx: TxQueue,
    previous: TxQueue,
    previous_heard: bool,
    /// Per board (bank order).
    tx_counts: Vec<TxCount>,
}

/// `floor(now * 1000 + 1e-6)`: seconds to whole ms, robust to float sums (`base.to_ms`).
pub fn to_ms(now: f64) -> i64 {
    (now * 1000.0 + 1e-6).floor() as i64
}

impl NeuronBank {
    /// Build the boards (bank order = tick order) with a send queue of `tx_capacity` frames.
    pub fn new(settings: &[BoardSettings], tx_capacity: usize) -> Result<NeuronBank, BankError> {
        if settings.is_empty() || settings.len() > 14 {
            return Err(BankError::BoardCount);
        }
        let mut boards = Vec::with_capacity(settings.len());
        for (k, s) in settings.iter().enumerate() {
            if settings.iter().take(k).any(|o| o.slave_id == s.slave_id) {
                return Err(BankError::DuplicateSlave(s.slave_id));
            }
            boards.push(NeuronBoard::new(s).map_err(|e| BankError::Board(k, e))?);
        }
        Ok(NeuronBank {
            tx_counts: vec![TxCount::default(); boards.len()],
            boards,
            tx: TxQueue::with_capacity(tx_capacity),
            previous: TxQueue::with_capacity(tx_capacity),
            previous_heard: false,
        })
    }

    /// The boards in bank order.
    pub fn boards(&self) -> &[NeuronBoard] {
        &self.boards
    }

    /// One board.
    pub fn board(&self, k: usize) -> Result<&NeuronBoard, BankError> {
        self.boards.get(k).ok_or(BankError::BoardIndex(k))
    }

    /// One board, mutable (IMU samples, test hooks).
    pub fn board_mut(&mut self, k: usize) -> Result<&mut NeuronBoard, BankError> {
        self.boards.get_mut(k).ok_or(BankError::BoardIndex(k))
    }

    /// A frame of board `board` (a [`Self::tick`] output) went to the bus (`sent`) or the bus
    /// refused it.
    pub fn count_tx(&mut self, board: usize, sent: bool) -> Result<(), BankError> {
        let c = self
            .tx_counts
            .get_mut(board)
            .ok_or(BankError::BoardIndex(board))?;
        if sent {
            c.sent += 1;
        } else {
            c.errors += 1;
        }
        Ok(())
    }

    /// Board `board`'s frames sent and refused.
    pub fn tx_count(&self, board: usize) -> Result<TxCount, BankError> {
        self.tx_counts
            .get(board)
            .copied()
            .ok_or(BankError::BoardIndex(board))
    }

    /// Fault hook: board `board`'s MCU resets at the call ([`NeuronBoard::power_cycle`]).
    pub fn power_cycle(&mut self, board: usize) -> Result<(), BankError> {
        self.board_mut(board)?.power_cycle();
        Ok(())
    }

    /// Plant feedback: servo `servo` of board `board` is at `ticks` (raw, float).
    pub fn set_position(
        &mut self,
        board: usize,
        servo: usize,
        ticks: f64,
    ) -> Result<(), BankError> {
        if !ticks.is_finite() {
            return Err(BankError::NonFinitePosition(board, servo));
        }
        let b = self.board_mut(board)?;
        let s = b
            .servos_mut()
            .get_mut(servo)
            .ok_or(BankError::ServoIndex(board, servo))?;
        s.position = ticks;
        Ok(())
    }

    /// Raw IMU sample (`sensor` 0 gyro, 1 acc, 2 mag) of one board.
    pub fn set_imu_raw(
        &mut self,
        board: usize,
        sensor: usize,
        xyz: [i16; 3],
    ) -> Result<(), BankError> {
        let b = self.board_mut(board)?;
        let slot = b.imu_raw.get_mut(sensor).ok_or(BankError::Sensor(sensor))?;
        *slot = xyz;
        Ok(())
    }

    /// Advance every board to `now` (s) with the frames pending on the bus; returns the
    /// frames to send, in order. Allocates nothing.
    pub fn tick(&mut self, now: f64, frames: &[RxFrame]) -> Result<&[TxEntry], BankError> {
        if !now.is_finite() {
            return Err(BankError::NonFiniteTime);
        }
        let now_ms = to_ms(now);
        self.tx.clear();
        for k in 0..self.boards.len() {
            let Some(board) = self.boards.get_mut(k) else {
                continue;
            };
            board.begin_tick(now_ms);
            // What the boards after this one sent last tick reached its queue first ...
            for j in 0..self.previous.len() {
                if let Some(e) = self.previous.get(j) {
                    if e.board > k {
                        board.receive(&RxFrame::from_sent(&e.frame), k, &mut self.tx);
                    }
                }
            }
            // ... then the bus frames, then what the boards before it sent this tick.
            for f in frames {
                board.receive(f, k, &mut self.tx);
            }
            let before = self.tx.len();
            let mut j = 0;
            while j < before {
                if let Some(e) = self.tx.get(j) {
                    if e.board < k {
                        board.receive(&RxFrame::from_sent(&e.frame), k, &mut self.tx);
                    }
                }
                j += 1;
            }
            board.end_tick(now, k, &mut self.tx);
        }
        self.previous.copy_from(&self.tx);
        self.previous_heard = self.previous.frames().iter().any(|e| {
            let field = (e.frame.id & 0xF) as u8;
            field == BROADCAST_ID
                || self
                    .boards
                    .iter()
                    .enumerate()
                    .any(|(k, b)| k != e.board && b.slave_id == field)
        });
        Ok(self.tx.frames())
    }

    /// True when a frame sent in the last tick passes another board's id filter (slave
    /// ids collide after a SET_SLAVE_ID): the next tick then handles more than the bus
    /// frames. Lets a caller skip work that only frames can need.
    pub fn sent_frames_heard(&self) -> bool {
        self.previous_heard
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_counters_are_per_board_and_checked() {
        let settings = [BoardSettings::new(1), BoardSettings::new(2)];
        let mut bank = NeuronBank::new(&settings, 16).expect("valid settings");
        bank.count_tx(1, true).unwrap();
        bank.count_tx(1, true).unwrap();
        bank.count_tx(1, false).unwrap();
        assert_eq!(bank.tx_count(0), Ok(TxCount::default()));
        assert_eq!(bank.tx_count(1), Ok(TxCount { sent: 2, errors: 1 }));
        assert_eq!(bank.count_tx(2, true), Err(BankError::BoardIndex(2)));
        assert_eq!(bank.tx_count(2), Err(BankError::BoardIndex(2)));
    }
}
