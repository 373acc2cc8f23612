//! The robot's sleep at rest (`rdm.plant.sleep.RestingSleep`, docs/plant.md "Sleeping at
//! rest"): in each step, once its controls are written, the sleep policy of the robot's trees
//! is "allowed" when every control equals the last step's and every rotor is stopped, else
//! "never"; a changed control finds a sleeping robot and wakes it in the same step (the caller
//! runs `mj_step1` again); MuJoCo's sleeping is on while the policy is "allowed" and for the
//! first "never" step after it (which resets MuJoCo's countdown to sleep).
//!
//! The state (the last controls, the flags, the wake count) lives here only; MuJoCo's arrays
//! (controls, tree sleep policy, tree-asleep) are the caller's slices.

/// A tree index outside the policy or tree-asleep array, or controls of a changed size.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SleepError {
    /// A robot tree index outside MuJoCo's tree arrays.
    TreeIndex(usize),
    /// The controls' length differs from the last step's.
    CtrlSize { want: usize, got: usize },
}

/// The rule and its state (see the module doc).
#[derive(Debug, Clone)]
pub struct RestingSleepRule {
    trees: Vec<usize>,
    rotors: Vec<usize>,
    allowed_value: i32,
    never_value: i32,
    last_ctrl: Vec<f64>,
    pending: bool,
    allowed: bool,
    wakes: u64,
    sleep_on: bool,
    settled: bool,
}

impl RestingSleepRule {
    /// The rule for the robot's `trees` and rotor actuators `rotors` (indices into the
    /// controls), with MuJoCo's policy values; `ctrl` the controls now. The policy written is
    /// "never" (the caller writes it once), sleeping on, the next step counted as changed.
    pub fn new(
        trees: Vec<usize>,
        rotors: Vec<usize>,
        allowed_value: i32,
        never_value: i32,
        ctrl: &[f64],
    ) -> Self {
        RestingSleepRule {
            trees,
            rotors,
            allowed_value,
            never_value,
            last_ctrl: ctrl.to_vec(),
            pending: true,
            allowed: false,
            wakes: 0,
            sleep_on: true,
            settled: false,
        }
    }

    /// The robot's trees.
    pub fn trees(&self) -> &[usize] {
        &self.trees
    }

    /// The rotor actuators.
    pub fn rotors(&self) -> &[usize] {
        &self.rotors
    }

    /// The controls of the last step.
    pub fn last_ctrl(&self) -> &[f64] {
        &self.last_ctrl
    }

    /// The next step counts as changed (start, reset, an outside change of the state).
    pub fn pending(&self) -> bool {
        self.pending
    }

    /// The policy now written for the trees ("allowed" true, "never" false).
    pub fn allowed(&self) -> bool {
        self.allowed
    }

    /// Steps that found the robot asleep and woke it for a changed control.
    pub fn wakes(&self) -> u64 {
        self.wakes
    }

    /// MuJoCo's sleeping (`mjENBL_SLEEP`) is on.
    pub fn sleep_on(&self) -> bool {
        self.sleep_on
    }

    /// A step ran with "never" and sleeping on since the policy was last "allowed".
    pub fn settled(&self) -> bool {
        self.settled
    }

    /// Treat the next step as changed.
    pub fn wake_next(&mut self) {
        self.pending = true;
    }

    /// Whether a robot tree is asleep (`tree_asleep[t] >= 0`).
    pub fn any_asleep(&self, tree_asleep: &[i32]) -> bool {
        self.trees
            .iter()
            .any(|&t| tree_asleep.get(t).is_some_and(|&v| v >= 0))
    }

    fn write_policy(&mut self, policy: &mut [i32], allowed: bool) -> Result<(), SleepError> {
        let value = if allowed {
            self.allowed_value
        } else {
            self.never_value
        };
        for &t in &self.trees {
            *policy.get_mut(t).ok_or(SleepError::TreeIndex(t))? = value;
        }
        self.allowed = allowed;
        Ok(())
    }

    /// This step's policy from its controls `ctrl`, written into `policy`. True: the policy
    /// went from "allowed" to "never" for a changed control: if [`Self::any_asleep`], the
    /// caller wakes the robot now (`mj_step1` on the same state) and calls [`Self::woke`].
    pub fn policy(&mut self, ctrl: &[f64], policy: &mut [i32]) -> Result<bool, SleepError> {
        if ctrl.len() != self.last_ctrl.len() {
            return Err(SleepError::CtrlSize {
                want: self.last_ctrl.len(),
                got: ctrl.len(),
            });
        }
        // element-wise == (NaN differs from itself)
        let same = !self.pending && ctrl.iter().zip(&self.last_ctrl).all(|(a, b)| a == b);
        if same {
            let stopped = self
                .rotors
                .iter()
                .all(|&r| ctrl.get(r).is_some_and(|&t| t == 0.0));
            if stopped != self.allowed {
                self.write_policy(policy, stopped)?;
            }
            return Ok(false);
        }
        self.pending = false;
        self.last_ctrl.copy_from_slice(ctrl);
        if !self.allowed {
            // "never" held through the last step: MuJoCo cannot have put the robot to sleep
            // (and a robot found asleep was woken when "never" was written)
            return Ok(false);
        }
        self.write_policy(policy, false)?;
        Ok(true)
    }

    /// The robot was woken in this step.
    pub fn woke(&mut self) {
        self.wakes += 1;
    }

    /// After [`Self::policy`]: MuJoCo's sleeping for this step's `mj_step2`, `Some(on)` when
    /// it changes (the caller sets or clears `mjENBL_SLEEP`).
    pub fn sleep_switch(&mut self) -> Option<bool> {
        let on = self.allowed || !self.settled;
        self.settled = !self.allowed;
        if on == self.sleep_on {
            return None;
        }
        self.sleep_on = on;
        Some(on)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const ALLOWED: i32 = 1;
    const NEVER: i32 = 2;

    /// One step of the rule: (policy of tree 1 after it, sleeping switch, wake check).
    fn step(
        r: &mut RestingSleepRule,
        ctrl: &[f64],
        policy: &mut [i32],
    ) -> (i32, Option<bool>, bool) {
        let check = r.policy(ctrl, policy).unwrap();
        (policy[1], r.sleep_switch(), check)
    }

    #[test]
    fn resting_with_rotors_stopped_allows_sleep_and_a_change_wakes() {
        // trees 1 and 3 are the robot's; rotors are controls 0 and 1, a servo is control 2
        let mut r = RestingSleepRule::new(vec![1, 3], vec![0, 1], ALLOWED, NEVER, &[0.0; 3]);
        let mut policy = [NEVER; 4];
        let rest = [0.0, 0.0, 0.3];
        // the first step counts as changed: never; sleeping stays on (first never step)
        assert_eq!(step(&mut r, &rest, &mut policy), (NEVER, None, false));
        assert!(r.settled());
        // the same controls, rotors stopped: allowed
        assert_eq!(step(&mut r, &rest, &mut policy), (ALLOWED, None, false));
        assert_eq!(policy, [NEVER, ALLOWED, NEVER, ALLOWED]);
        // a servo goal changes: never, and the caller checks for a sleeping robot
        let moved = [0.0, 0.0, 0.4];
        assert_eq!(step(&mut r, &moved, &mut policy), (NEVER, None, true));
        assert!(r.any_asleep(&[-1, 0, -1, -1]) && !r.any_asleep(&[0, -1, 0, -1]));
        r.woke();
        assert_eq!(r.wakes(), 1);
        assert_eq!(r.last_ctrl(), &moved);
        // still the same, rotors stopped: allowed again
        assert_eq!(step(&mut r, &moved, &mut policy), (ALLOWED, None, false));
        // rotors spin: never; MuJoCo's sleeping goes off after the first never step
        let flying = [1.0, 1.0, 0.4];
        assert_eq!(step(&mut r, &flying, &mut policy), (NEVER, None, true));
        assert_eq!(
            step(&mut r, &flying, &mut policy),
            (NEVER, Some(false), false)
        );
        assert!(!r.sleep_on());
        // a steady flight keeps it off; back at rest it comes on with "allowed"
        assert_eq!(step(&mut r, &flying, &mut policy), (NEVER, None, false));
        assert_eq!(step(&mut r, &rest, &mut policy), (NEVER, None, false));
        assert_eq!(
            step(&mut r, &rest, &mut policy),
            (ALLOWED, Some(true), false)
        );
    }

    #[test]
    fn nan_controls_count_as_changed_and_bad_sizes_are_refused() {
        let mut r = RestingSleepRule::new(vec![1], vec![0], ALLOWED, NEVER, &[0.0; 2]);
        let mut policy = [NEVER; 2];
        let c = [0.0, f64::NAN];
        step(&mut r, &c, &mut policy);
        assert_eq!(step(&mut r, &c, &mut policy).0, NEVER); // NaN != NaN: changed
        assert!(r.policy(&[0.0; 3], &mut policy).is_err());
        r.wake_next();
        assert!(r.pending());
        let mut r = RestingSleepRule::new(vec![5], vec![], ALLOWED, NEVER, &[0.0]);
        r.policy(&[0.0], &mut policy).unwrap();
        assert_eq!(r.policy(&[0.0], &mut policy), Err(SleepError::TreeIndex(5)));
    }
}
