//! The per-millisecond plant <-> Neuron-bank coupling of the plant bridge
//! (`rdm.nodes.plant_bridge.PlantBridge.tick`, steps 1, 2 and 4) in one call.
//!
//! Same arithmetic, in the same order, as the Python reference, so a run with either path
//! writes the same files:
//! - snapshot: the joint angles at the bridge tick (`qpos[qadr[j]]`); the present positions
//!   `center + q * ticks_per_rad` are pushed to the boards only when the bank needs them
//!   (once per snapshot), as the reference's lazily read joint feed;
//! - goals of servos with torque on -> servo targets `(goal - center) / ticks_per_rad` (rad),
//!   read only from boards whose change counter moved;
//! - ESC outputs -> rotor duties `pulse_us / 2000` of those boards.

use super::neuron_bank::NeuronBank;

/// ESC PWM frame period of the Neuron timer [us] (500 Hz), as `rdm.nodes.esc_model`.
const ESC_PERIOD_US: f64 = 2000.0;

/// Why a bridge could not be built or stepped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BridgeError {
    /// A servo entry names a board or servo the bank does not have (entry index).
    ServoEntry(usize),
    /// A servo entry's joint index is outside the joint table (entry index).
    JointIndex(usize),
    /// A rotor entry names a board the bank does not have, or a rotor outside `duties`.
    RotorEntry(usize),
    /// A joint's qpos address is outside the `qpos` given (joint index).
    QposAddress(usize),
    /// A ticks-per-radian scale is zero or not finite (joint index).
    Scale(usize),
    /// `targets` / `duties` length differs from the joint / rotor count.
    Length,
    /// A snapshot joint angle is not finite (joint index).
    NonFiniteJoint(usize),
}

/// One mapped servo: board, servo index on the board, joint index (joint_order).
#[derive(Debug, Clone, Copy)]
pub struct ServoEntry {
    /// Board index in the bank.
    pub board: usize,
    /// Servo index on the board.
    pub servo: usize,
    /// Joint index (plant joint_order).
    pub joint: usize,
}

/// Which outputs changed in one [`BankBridge::couple`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Coupled {
    /// A servo target moved (the plant's servo targets must be re-commanded).
    pub targets: bool,
    /// A rotor duty moved.
    pub duties: bool,
}

/// The index maps and state of the coupling; sized at setup, allocation-free per tick.
#[derive(Debug, Clone)]
pub struct BankBridge {
    center: i64,
    qadr: Vec<usize>,
    scale: Vec<f64>,
    servos: Vec<ServoEntry>,
    /// (rotor index, board index)
    rotors: Vec<(usize, usize)>,
    /// Board index of each servo group, in layout order, with its entries' range.
    groups: Vec<(usize, usize, usize)>,
    seen: Vec<Option<u64>>,
    last_goal: Vec<Option<i64>>,
    q: Vec<f64>,
    epoch: u64,
    pushed_epoch: Option<u64>,
}

impl BankBridge {
    /// `servos` grouped by board in layout order (the reference reads boards in that order);
    /// `qadr[j]` / `scale[j]`: qpos address and ticks per radian of joint `j`.
    pub fn new(
        bank: &NeuronBank,
        center: i64,
        qadr: &[usize],
        scale: &[f64],
        servos: &[ServoEntry],
        rotors: &[(usize, usize)],
        group_boards: &[usize],
    ) -> Result<BankBridge, BridgeError> {
        if qadr.len() != scale.len() {
            return Err(BridgeError::Length);
        }
        for (j, s) in scale.iter().enumerate() {
            if !s.is_finite() || *s == 0.0 {
                return Err(BridgeError::Scale(j));
            }
        }
        for (n, e) in servos.iter().enumerate() {
            let ok = bank
                .board(e.board)
                .is_ok_and(|b| e.servo < b.servos().len());
            if !ok {
                return Err(BridgeError::ServoEntry(n));
            }
            if e.joint >= qadr.len() {
                return Err(BridgeError::JointIndex(n));
            }
        }
        for (n, (_, b)) in rotors.iter().enumerate() {
            if bank.board(*b).is_err() {
                return Err(BridgeError::RotorEntry(n));
            }
        }
        // A group per board of `group_boards`: its servo entries are contiguous.
        let mut groups = Vec::with_capacity(group_boards.len());
        let mut start = 0;
        for (n, b) in group_boards.iter().enumerate() {
            if bank.board(*b).is_err() {
                return Err(BridgeError::ServoEntry(n));
            }
            let len = servos
                .get(start..)
                .map_or(0, |rest| rest.iter().take_while(|e| e.board == *b).count());
            groups.push((*b, start, start + len));
            start += len;
        }
        if start != servos.len() {
            return Err(BridgeError::ServoEntry(start));
        }
        Ok(BankBridge {
            center,
            qadr: qadr.to_vec(),
            scale: scale.to_vec(),
            servos: servos.to_vec(),
            rotors: rotors.to_vec(),
            seen: vec![None; groups.len()],
            groups,
            last_goal: vec![None; servos.len()],
            q: vec![0.0; qadr.len()],
            epoch: 0,
            pushed_epoch: None,
        })
    }

    /// Snapshot of the joint angles at this tick (`qpos`: the plant's whole qpos).
    pub fn snapshot(&mut self, qpos: &[f64]) -> Result<(), BridgeError> {
        for (j, a) in self.qadr.iter().enumerate() {
            let v = qpos.get(*a).ok_or(BridgeError::QposAddress(j))?;
            if let Some(slot) = self.q.get_mut(j) {
                *slot = *v;
            }
        }
        self.epoch = self.epoch.wrapping_add(1);
        Ok(())
    }

    /// Push the snapshot's present positions (raw ticks) to every mapped servo, once per
    /// snapshot; a non-finite joint angle is an error (nothing after it is pushed).
    pub fn push_positions(&mut self, bank: &mut NeuronBank) -> Result<(), BridgeError> {
        if self.pushed_epoch == Some(self.epoch) {
            return Ok(());
        }
        self.pushed_epoch = Some(self.epoch);
        for (n, e) in self.servos.iter().enumerate() {
            let q = self.q.get(e.joint).copied().unwrap_or(f64::NAN);
            let s = self.scale.get(e.joint).copied().unwrap_or(f64::NAN);
            // Two IEEE operations, as the reference's `center + q * scale`.
            let ticks = self.center as f64 + q * s;
            bank.set_position(e.board, e.servo, ticks).map_err(|_| {
                if ticks.is_finite() {
                    BridgeError::ServoEntry(n)
                } else {
                    BridgeError::NonFiniteJoint(e.joint)
                }
            })?;
        }
        Ok(())
    }

    /// Goals -> `targets` (rad, joint_order) and ESC outputs -> `duties`, for boards whose
    /// change counter moved since the last call.
    pub fn couple(
        &mut self,
        bank: &NeuronBank,
        targets: &mut [f64],
        duties: &mut [f64],
    ) -> Result<Coupled, BridgeError> {
        if targets.len() != self.qadr.len() {
            return Err(BridgeError::Length);
        }
        let mut out = Coupled::default();
        let mut any_changed = false;
        for (g, (b, start, end)) in self.groups.iter().enumerate() {
            let board = bank
                .board(*b)
                .map_err(|_| BridgeError::ServoEntry(*start))?;
            let c = Some(board.changes);
            let Some(seen) = self.seen.get_mut(g) else {
                continue;
            };
            if *seen == c {
                continue;
            }
            *seen = c;
            any_changed = true;
            let models = board.servos();
            for n in *start..*end {
                let (Some(e), Some(last)) = (self.servos.get(n), self.last_goal.get_mut(n)) else {
                    continue;
                };
                let Some(servo) = models.get(e.servo) else {
                    continue;
                };
                let goal = servo.goal();
                if servo.torque_enable() && *last != Some(goal) {
                    *last = Some(goal);
                    let s = self.scale.get(e.joint).copied().unwrap_or(f64::NAN);
                    // The reference: Python int (goal - center) / float64 scale.
                    let rad = (goal - self.center) as f64 / s;
                    if let Some(t) = targets.get_mut(e.joint) {
                        if rad != *t {
                            *t = rad;
                            out.targets = true;
                        }
                    }
                }
            }
        }
        if any_changed {
            for (n, (r, b)) in self.rotors.iter().enumerate() {
                let board = bank.board(*b).map_err(|_| BridgeError::RotorEntry(n))?;
                let duty = (f64::from(board.esc_value()) + 1000.0) / ESC_PERIOD_US;
                let slot = duties.get_mut(*r).ok_or(BridgeError::RotorEntry(n))?;
                if duty != *slot {
                    *slot = duty;
                    out.duties = true;
                }
            }
        }
        Ok(out)
    }
}
