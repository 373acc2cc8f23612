//! The per-millisecond plant <-> Neuron-bank coupling of the plant bridge
//! (`rdm.nodes.plant_bridge.PlantBridge.tick`, steps 1, 2 and 4) in one call per bank:
//! - snapshot: the joint angles at the bridge tick (`qpos[qadr[j]]`); the present positions
//!   `center + q * ticks_per_rad` are pushed to the boards only when the bank needs them
//!   (once per snapshot);
//! - goals of servos with torque on -> servo targets `(goal - center) / ticks_per_rad` (rad),
//!   read only from boards whose change counter moved;
//! - ESC outputs -> rotor duties `pulse_us / 2000` of those boards.
//!
//! Fault hook (the fault campaign's `stuck-servo`): [`BankBridge::stick_joint`] makes a
//! joint's servo stop following its goal: its target is frozen at the joint angle of the
//! next snapshot and no later goal reaches it. Off (no joint stuck), nothing of it runs.

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
    /// Per joint: its output shaft stopped following the goal (fault hook).
    stuck: Vec<bool>,
    /// A joint stuck since the last coupling: its target still to be frozen.
    stick_pending: bool,
}

impl BankBridge {
    /// `servos` grouped by board in layout order (boards are read in that order);
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
            stuck: vec![false; qadr.len()],
            stick_pending: false,
        })
    }

    /// Fault hook: joint `joint`'s servo output stops following its goal from the next
    /// coupling on (its target frozen at that snapshot's angle). Returns false (nothing
    /// changed) for a joint outside the joint table.
    pub fn stick_joint(&mut self, joint: usize) -> bool {
        match self.stuck.get_mut(joint) {
            Some(s) => {
                *s = true;
                self.stick_pending = true;
                true
            }
            None => false,
        }
    }

    /// The joints whose servo is stuck (fault hook), in joint order.
    pub fn stuck_joints(&self) -> impl Iterator<Item = usize> + '_ {
        self.stuck
            .iter()
            .enumerate()
            .filter_map(|(j, s)| s.then_some(j))
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
            // Two IEEE operations: `center + q * scale`.
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
        if self.stick_pending {
            self.stick_pending = false;
            for (j, stuck) in self.stuck.iter().enumerate() {
                let (Some(t), Some(q)) = (targets.get_mut(j), self.q.get(j)) else {
                    continue;
                };
                if *stuck && *t != *q {
                    *t = *q;
                    out.targets = true;
                }
            }
        }
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
                if self.stuck.get(e.joint).copied().unwrap_or(false) {
                    continue; // the shaft no longer follows (fault hook)
                }
                if servo.torque_enable() && *last != Some(goal) {
                    *last = Some(goal);
                    let s = self.scale.get(e.joint).copied().unwrap_or(f64::NAN);
                    // Integer (goal - center), then one float64 division by the scale.
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::firmware::neuron_board::BoardSettings;

    /// Torque on and a goal of `ticks` on the one servo of board 0 (as CAN frames would).
    fn command(bank: &mut NeuronBank, ticks: i64) {
        let b = bank.board_mut(0).expect("board 0");
        let mut changes = b.changes;
        let servo = &mut b.servos_mut()[0];
        servo.set_torque(true, &mut changes);
        assert!(servo.command_goal(ticks, true, &mut changes));
        b.changes = changes;
    }

    #[test]
    fn a_stuck_joint_keeps_the_angle_it_stuck_at() {
        let mut s = BoardSettings::new(1);
        s.servo_count = 1;
        s.plant_driven = true;
        let mut bank = NeuronBank::new(&[s], 16).expect("bank");
        let entry = ServoEntry {
            board: 0,
            servo: 0,
            joint: 0,
        };
        let mut bridge =
            BankBridge::new(&bank, 2048, &[0], &[1000.0], &[entry], &[], &[0]).expect("bridge");
        let (mut targets, mut duties) = ([0.0], [0.0; 0]);
        command(&mut bank, 2548);
        bridge.snapshot(&[0.1]).expect("snapshot");
        let c = bridge
            .couple(&bank, &mut targets, &mut duties)
            .expect("couple");
        assert!(c.targets);
        assert_eq!(targets, [0.5]); // (2548 - 2048) / 1000
        assert!(bridge.stick_joint(0));
        assert!(!bridge.stick_joint(1)); // outside the joint table
        bridge.snapshot(&[0.3]).expect("snapshot");
        let c = bridge
            .couple(&bank, &mut targets, &mut duties)
            .expect("couple");
        assert!(c.targets);
        assert_eq!(targets, [0.3]); // frozen where the shaft was
        command(&mut bank, 2948);
        bridge.snapshot(&[0.31]).expect("snapshot");
        let c = bridge
            .couple(&bank, &mut targets, &mut duties)
            .expect("couple");
        assert!(!c.targets);
        assert_eq!(targets, [0.3]); // a later goal no longer reaches it
        assert_eq!(bridge.stuck_joints().collect::<Vec<_>>(), vec![0]);
    }
}
