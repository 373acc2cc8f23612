//! `rdm.plant.sleep.RestingSleep` in the kernel's plant step: the robot's trees may sleep
//! while this step's controls equal the last step's and its rotors are stopped, and a changed
//! control wakes a sleeping robot in the same step (`mj_step1` again on the same state, then
//! `mj_step2`). The same arrays as the Python rule; its flags are read with the plan (`load`)
//! and written back before any Python code runs (`flush`).

use numpy::PyArray1;
use pyo3::prelude::*;

use super::attr::Name;
use crate::untracked;

struct Names {
    pending: Name,
    allowed: Name,
    wakes: Name,
    sleep_on: Name,
    settled: Name,
    enableflags: Name,
}

/// What `LockstepKernel.attach_plant` is given of `Plant.sleep` (a `RestingSleep`): the
/// object (its flags are the plan), its trees and rotor actuators, the policy values
/// `ALLOWED` / `NEVER` and `SLEEP_ENABLE_BIT` of `rdm.plant.sleep`, its policy, tree-asleep
/// and last-control arrays and `model.opt`.
pub(crate) struct SleepParts {
    pub(crate) obj: Py<PyAny>,
    pub(crate) trees: Vec<usize>,
    pub(crate) rotors: Vec<usize>,
    pub(crate) allowed_value: i32,
    pub(crate) never_value: i32,
    pub(crate) sleep_bit: i64,
    pub(crate) policy: Py<PyArray1<i32>>,
    pub(crate) tree_asleep: Py<PyArray1<i32>>,
    pub(crate) last_ctrl: Py<PyArray1<f64>>,
    pub(crate) opt: Py<PyAny>,
}

/// The Python object's arrays and flags as the kernel drives them.
pub(crate) struct SleepLink {
    obj: Py<PyAny>,
    trees: Vec<usize>,
    rotors: Vec<usize>,
    allowed_value: i32,
    never_value: i32,
    policy: Py<PyArray1<i32>>,
    tree_asleep: Py<PyArray1<i32>>,
    last_ctrl: Py<PyArray1<f64>>,
    /// `model.opt` and `mjENBL_SLEEP` (MuJoCo's sleeping, on only while it can matter).
    opt: Py<PyAny>,
    sleep_bit: i64,
    names: Names,
    pending: bool,
    allowed: bool,
    wakes: i64,
    sleep_on: bool,
    settled: bool,
    dirty: bool,
}

impl SleepLink {
    /// The policy written now is "allowed" (the robot may fall asleep in this step).
    pub(crate) fn allowed(&self) -> bool {
        self.allowed
    }

    /// `RestingSleep` `obj` with its construction-time parts (typed, read by the caller).
    pub(crate) fn new(py: Python<'_>, parts: SleepParts) -> Self {
        let names = Names {
            pending: Name::new(py, "pending"),
            allowed: Name::new(py, "allowed"),
            wakes: Name::new(py, "wakes"),
            sleep_on: Name::new(py, "sleep_on"),
            settled: Name::new(py, "settled"),
            enableflags: Name::new(py, "enableflags"),
        };
        // the flags come with the plan (`load`, before any step)
        SleepLink {
            obj: parts.obj,
            trees: parts.trees,
            rotors: parts.rotors,
            allowed_value: parts.allowed_value,
            never_value: parts.never_value,
            policy: parts.policy,
            tree_asleep: parts.tree_asleep,
            last_ctrl: parts.last_ctrl,
            opt: parts.opt,
            sleep_bit: parts.sleep_bit,
            names,
            pending: true,
            allowed: false,
            wakes: 0,
            sleep_on: true,
            settled: false,
            dirty: false,
        }
    }

    /// Re-read the flags (Python code may have run).
    pub(crate) fn load(&mut self, py: Python<'_>) -> PyResult<()> {
        let obj = self.obj.bind(py);
        self.pending = self.names.pending.truthy(obj)?;
        self.allowed = self.names.allowed.truthy(obj)?;
        self.wakes = self.names.wakes.i64(obj)?;
        self.sleep_on = self.names.sleep_on.truthy(obj)?;
        self.settled = self.names.settled.truthy(obj)?;
        self.dirty = false;
        Ok(())
    }

    /// Write the flags back.
    pub(crate) fn flush(&mut self, py: Python<'_>) -> PyResult<()> {
        if !self.dirty {
            return Ok(());
        }
        let obj = self.obj.bind(py);
        self.names.pending.set(obj, self.pending)?;
        self.names.allowed.set(obj, self.allowed)?;
        self.names.wakes.set(obj, self.wakes)?;
        self.names.sleep_on.set(obj, self.sleep_on)?;
        self.names.settled.set(obj, self.settled)?;
        self.dirty = false;
        Ok(())
    }

    fn write_policy(&mut self, py: Python<'_>, allowed: bool) -> PyResult<()> {
        let value = if allowed {
            self.allowed_value
        } else {
            self.never_value
        };
        // SAFETY: MuJoCo's tree sleep policy, written only here, no Python runs while the
        // slice lives (untracked.rs).
        let policy = unsafe { untracked::write(self.policy.bind(py), "tree sleep policy") }?;
        for &t in &self.trees {
            *policy.get_mut(t).ok_or_else(tree_out_of_range)? = value;
        }
        self.allowed = allowed;
        self.dirty = true;
        Ok(())
    }

    /// `RestingSleep.before_step2` with `ctrl` the step's controls; `step1` wakes.
    pub(crate) fn before_step2(
        &mut self,
        py: Python<'_>,
        ctrl: &Bound<'_, PyArray1<f64>>,
        step1: impl FnOnce() -> PyResult<()>,
    ) -> PyResult<()> {
        self.policy(py, ctrl, step1)?;
        // on while "allowed" and for the first "never" step (RestingSleep.before_step2);
        // after any "never" step the countdown is reset: settled
        let on = self.allowed || !self.settled;
        let settled = !self.allowed;
        if settled != self.settled {
            self.settled = settled;
            self.dirty = true;
        }
        if on != self.sleep_on {
            self.dirty = true;
            let opt = self.opt.bind(py);
            let flags = self.names.enableflags.i64(opt)?;
            let flags = if on {
                flags | self.sleep_bit
            } else {
                flags & !self.sleep_bit
            };
            self.names.enableflags.set(opt, flags)?;
            self.sleep_on = on;
        }
        Ok(())
    }

    /// `RestingSleep._policy`: the policy of this step, a sleeping robot woken.
    fn policy(
        &mut self,
        py: Python<'_>,
        ctrl: &Bound<'_, PyArray1<f64>>,
        step1: impl FnOnce() -> PyResult<()>,
    ) -> PyResult<()> {
        let (same, stopped) = {
            let last = self.last_ctrl.bind(py);
            if !untracked::disjoint(ctrl, last) {
                return Err(pyo3::exceptions::PyValueError::new_err(
                    "ctrl: shares memory with the last controls",
                ));
            }
            // SAFETY: disjoint buffers (checked above), no Python runs while the slices live
            // (untracked.rs).
            let (ctrl, last) = unsafe {
                (
                    untracked::read(ctrl, "ctrl")?,
                    untracked::write(last, "last ctrl")?,
                )
            };
            if last.len() != ctrl.len() {
                return Err(pyo3::exceptions::PyValueError::new_err(
                    "ctrl: size changed",
                ));
            }
            // np.array_equal: element-wise ==
            let same = !self.pending && ctrl.iter().zip(last.iter()).all(|(a, b)| a == b);
            if !same {
                last.copy_from_slice(ctrl);
            }
            let stopped = self
                .rotors
                .iter()
                .all(|&r| ctrl.get(r).is_some_and(|&t| t == 0.0));
            (same, stopped)
        };
        if same {
            if stopped != self.allowed {
                self.write_policy(py, stopped)?;
            }
            return Ok(());
        }
        self.pending = false;
        self.dirty = true;
        if !self.allowed {
            // "never" held through the last step: MuJoCo cannot have put the robot to sleep
            // (and a robot found asleep was woken when "never" was written)
            return Ok(());
        }
        self.write_policy(py, false)?;
        let asleep = {
            // SAFETY: read only, no Python runs while the slice lives (untracked.rs).
            let a = unsafe { untracked::read(self.tree_asleep.bind(py), "tree_asleep") }?;
            self.trees
                .iter()
                .any(|&t| a.get(t).is_some_and(|&v| v >= 0))
        };
        if asleep {
            step1()?;
            self.wakes += 1;
        }
        Ok(())
    }
}

fn tree_out_of_range() -> PyErr {
    pyo3::exceptions::PyIndexError::new_err("sleep: tree index out of range")
}
