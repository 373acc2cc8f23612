//! `RestingSleepCore`: `rdm_core::sim::resting_sleep::RestingSleepRule` on MuJoCo's arrays
//! (controls, tree sleep policy, tree-asleep; views stable for the model's and data's life)
//! and `opt.enableflags`: the one owner of the robot's sleep-at-rest state. Its Python face is
//! `rdm.plant.sleep.RestingSleep`; the lockstep kernel's plant step calls the same object.

use numpy::{PyArray1, PyArrayMethods};
use pyo3::exceptions::{PyIndexError, PyValueError};
use pyo3::prelude::*;
use rdm_core::sim::resting_sleep::{RestingSleepRule, SleepError};

use crate::untracked;

/// The robot's sleep at rest (see the module doc).
#[pyclass(module = "rdm._rdm")]
pub struct RestingSleepCore {
    rule: RestingSleepRule,
    ctrl: Py<PyArray1<f64>>,
    policy: Py<PyArray1<i32>>,
    tree_asleep: Py<PyArray1<i32>>,
    /// `model.opt` and `mjENBL_SLEEP`.
    opt: Py<PyAny>,
    sleep_bit: i64,
}

fn sleep_error(e: SleepError) -> PyErr {
    match e {
        SleepError::TreeIndex(t) => {
            PyIndexError::new_err(format!("sleep: tree index {t} out of range"))
        }
        SleepError::CtrlSize { want, got } => PyValueError::new_err(format!(
            "sleep: ctrl has {got} values, the last step's had {want}"
        )),
    }
}

impl RestingSleepCore {
    /// The policy written now is "allowed" (the robot may fall asleep in this step).
    pub(crate) fn is_allowed(&self) -> bool {
        self.rule.allowed()
    }

    /// This step's rule once its controls are written; `step1` (`mj_step1` on the same
    /// state) wakes a sleeping robot; then MuJoCo's sleeping on or off for `mj_step2`.
    pub(crate) fn run_before_step2(
        &mut self,
        py: Python<'_>,
        step1: impl FnOnce() -> PyResult<()>,
    ) -> PyResult<()> {
        let check = {
            // SAFETY: MuJoCo's controls (read) and tree sleep policy (written only here), two
            // distinct arrays of different types; no Python runs while the slices live
            // (untracked.rs).
            let (ctrl, policy) = unsafe {
                (
                    untracked::read(self.ctrl.bind(py), "ctrl")?,
                    untracked::write(self.policy.bind(py), "tree sleep policy")?,
                )
            };
            self.rule.policy(ctrl, policy).map_err(sleep_error)?
        };
        if check {
            let asleep = {
                // SAFETY: read only, no Python runs while the slice lives (untracked.rs).
                let a = unsafe { untracked::read(self.tree_asleep.bind(py), "tree_asleep") }?;
                self.rule.any_asleep(a)
            };
            if asleep {
                step1()?;
                self.rule.woke();
            }
        }
        if let Some(on) = self.rule.sleep_switch() {
            let opt = self.opt.bind(py);
            let name = pyo3::intern!(py, "enableflags");
            let flags: i64 = opt.getattr(name)?.extract()?;
            let bit = self.sleep_bit;
            opt.setattr(name, if on { flags | bit } else { flags & !bit })?;
        }
        Ok(())
    }
}

#[pymethods]
impl RestingSleepCore {
    /// The rule for the robot's `trees` and rotor actuators `rotors`, MuJoCo's policy values
    /// `allowed_value` / `never_value` and `sleep_bit` (`mjENBL_SLEEP`), on the views
    /// `ctrl` (`data.ctrl`), `policy` (`model.tree_sleep_policy`), `tree_asleep`
    /// (`data.tree_asleep`) and `opt` (`model.opt`). The last controls start as `ctrl` now.
    #[new]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        trees: Vec<usize>,
        rotors: Vec<usize>,
        allowed_value: i32,
        never_value: i32,
        sleep_bit: i64,
        ctrl: Py<PyArray1<f64>>,
        policy: Py<PyArray1<i32>>,
        tree_asleep: Py<PyArray1<i32>>,
        opt: Py<PyAny>,
    ) -> PyResult<Self> {
        let n_trees = policy.bind(py).len()?;
        if let Some(&t) = trees.iter().find(|&&t| t >= n_trees) {
            return Err(sleep_error(SleepError::TreeIndex(t)));
        }
        let c = ctrl.bind(py).to_vec()?;
        if let Some(&r) = rotors.iter().find(|&&r| r >= c.len()) {
            return Err(PyIndexError::new_err(format!(
                "sleep: rotor actuator {r} out of range"
            )));
        }
        Ok(RestingSleepCore {
            rule: RestingSleepRule::new(trees, rotors, allowed_value, never_value, &c),
            ctrl,
            policy,
            tree_asleep,
            opt,
            sleep_bit,
        })
    }

    /// This step's rule (see `run_before_step2`); `step1()` wakes a sleeping robot.
    fn before_step2(&mut self, py: Python<'_>, step1: &Bound<'_, PyAny>) -> PyResult<()> {
        self.run_before_step2(py, || step1.call0().map(|_| ()))
    }

    /// Treat the next step as changed.
    fn wake_next(&mut self) {
        self.rule.wake_next();
    }

    /// Whether a robot tree is asleep.
    fn asleep(&self, py: Python<'_>) -> PyResult<bool> {
        // SAFETY: read only, no Python runs while the slice lives (untracked.rs).
        let a = unsafe { untracked::read(self.tree_asleep.bind(py), "tree_asleep") }?;
        Ok(self.rule.any_asleep(a))
    }

    #[getter]
    fn trees(&self) -> Vec<usize> {
        self.rule.trees().to_vec()
    }

    #[getter]
    fn rotors(&self) -> Vec<usize> {
        self.rule.rotors().to_vec()
    }

    /// The controls of the last step (a copy).
    #[getter]
    fn last_ctrl<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_slice(py, self.rule.last_ctrl())
    }

    #[getter]
    fn pending(&self) -> bool {
        self.rule.pending()
    }

    #[getter]
    fn allowed(&self) -> bool {
        self.rule.allowed()
    }

    #[getter]
    fn wakes(&self) -> u64 {
        self.rule.wakes()
    }

    #[getter]
    fn sleep_on(&self) -> bool {
        self.rule.sleep_on()
    }

    #[getter]
    fn settled(&self) -> bool {
        self.rule.settled()
    }
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<RestingSleepCore>()?;
    Ok(())
}
