//! The plant's state between calls that `rdm.plant.Plant` and the lockstep kernel both
//! change: the lazy forward pass (whether the derived quantities are stale, whether the next
//! step needs `mj_step1`), the state version the ground-truth cache keys on, the count of
//! rejected servo goals, and whether a step can run without Python (rotor models in the Rust
//! core, no held external wrench). One form: `_rdm.PlantStateCore` holds it for both.

/// The plant's shared state (see the module doc). Allocates nothing.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PlantState {
    /// True after a step until the lazy `mj_forward` ran.
    pub stale: bool,
    /// The next step runs `mj_step1` (false only right after a forward pass on this state).
    pub needs_step1: bool,
    /// Changes with every step, reset and outside access to the data.
    pub version: u64,
    /// Non-finite servo goals refused.
    pub rejected_commands: u64,
    /// Every rotor's ceiling model is in the Rust rotor core.
    pub rotors_in_core: bool,
    /// An external wrench is held (it is re-aimed in Python at every step and forward pass).
    pub wrenches_held: bool,
}

impl Default for PlantState {
    fn default() -> Self {
        Self::new()
    }
}

impl PlantState {
    /// A fresh plant: not stale, its first step runs `mj_step1`.
    pub fn new() -> Self {
        PlantState {
            stale: false,
            needs_step1: true,
            version: 0,
            rejected_commands: 0,
            rotors_in_core: false,
            wrenches_held: false,
        }
    }

    /// A forward pass ran on the present state (`Plant.sync`): nothing is stale and the
    /// pass covers the next step's `mj_step1` stages.
    pub fn synced(&mut self) {
        self.stale = false;
        self.needs_step1 = false;
    }

    /// The caller may change the state (`Plant.data`): the next step runs `mj_step1` and
    /// the version moves on.
    pub fn touched(&mut self) {
        self.needs_step1 = true;
        self.version = self.version.wrapping_add(1);
    }

    /// The plant was reset and forwarded (`Plant.reset`).
    pub fn reset(&mut self) {
        self.stale = false;
        self.touched();
    }

    /// One step's passes begin: whether `mj_step1` must run (the state is stale or was
    /// changed since the last forward pass). Every later step runs it.
    pub fn begin_step(&mut self) -> bool {
        let step1 = self.stale || self.needs_step1;
        self.needs_step1 = true;
        step1
    }

    /// Steps ran: the forward pass waits for the next reading, the version moves on.
    pub fn stepped(&mut self) {
        self.stale = true;
        self.needs_step1 = true;
        self.version = self.version.wrapping_add(1);
    }

    /// A step can run without Python: rotor models in the core and no held wrench.
    pub fn step_in_core(&self) -> bool {
        self.rotors_in_core && !self.wrenches_held
    }

    /// Count `n` refused servo goals.
    pub fn reject(&mut self, n: u64) {
        self.rejected_commands = self.rejected_commands.saturating_add(n);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_forward_pass_spares_only_the_next_step1() {
        let mut s = PlantState::new();
        assert!(s.begin_step(), "a fresh plant runs mj_step1");
        s.stepped();
        assert!(s.stale && s.version == 1);
        s.synced();
        assert!(!s.stale);
        assert!(!s.begin_step(), "the forward pass covered mj_step1");
        assert!(s.begin_step(), "the second step of a step(n) runs it");
        s.stepped();
        s.synced();
        s.touched();
        assert!(s.begin_step(), "outside access to the data needs mj_step1");
        assert_eq!(s.version, 3);
    }

    #[test]
    fn reset_clears_stale_and_step_in_core_needs_both_conditions() {
        let mut s = PlantState::new();
        s.stepped();
        s.reset();
        assert!(!s.stale && s.needs_step1 && s.version == 2);
        assert!(!s.step_in_core());
        s.rotors_in_core = true;
        assert!(s.step_in_core());
        s.wrenches_held = true;
        assert!(!s.step_in_core());
        s.reject(2);
        s.reject(u64::MAX);
        assert_eq!(s.rejected_commands, u64::MAX);
    }
}
