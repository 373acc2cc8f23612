//! The lockstep loop's inner work: the fast parts' boundaries (flush before Python runs,
//! invalidate after), one millisecond's node ticks and physics step, and `run`'s loop.

use super::*;

impl LockstepKernel {
    /// Every attached fast part with its mask bit.
    pub(super) fn parts(&mut self) -> [(u8, Option<&mut dyn Part>); 5] {
        [
            (PLANT, self.plant.as_mut().map(|p| p as &mut dyn Part)),
            (BRIDGE, self.bridge.as_mut().map(|p| p as &mut dyn Part)),
            (BANK, self.bank.as_mut().map(|p| p as &mut dyn Part)),
            (SPINAL, self.spinal.as_mut().map(|p| p as &mut dyn Part)),
            (LEPTRINO, self.leptrino.as_mut().map(|p| p as &mut dyn Part)),
        ]
    }

    /// Write back the deferred state of the parts in `mask`.
    pub(super) fn flush(&mut self, py: Python<'_>, mask: u8) -> PyResult<()> {
        for (bit, part) in self.parts() {
            if let (true, Some(part)) = (mask & bit != 0, part) {
                part.flush(py)?;
            }
        }
        Ok(())
    }

    /// Forget the plans of the parts in `mask` (Python code may have changed them).
    pub(super) fn invalidate(&mut self, mask: u8) {
        for (bit, part) in self.parts() {
            if let (true, Some(part)) = (mask & bit != 0, part) {
                part.invalidate();
            }
        }
    }

    /// Before Python code that may read or change the parts in `mask` runs at time `t`:
    /// their deferred state written, the clock set. (The other parts' deferred state waits:
    /// that code neither reads nor changes it.)
    pub(super) fn enter_python(&mut self, py: Python<'_>, t: f64, mask: u8) -> PyResult<()> {
        self.boundaries += 1;
        self.flush(py, mask)?;
        if self.clock_t != Some(t) {
            self.clock.bind(py).setattr("now", t)?;
            self.clock_t = Some(t);
        }
        Ok(())
    }

    /// After Python code ran: the plans of the parts in `mask` (what it may have changed;
    /// the same mask as `enter_python`'s) are re-read on their next use.
    pub(super) fn leave_python(&mut self, mask: u8) {
        self.invalidate(mask);
    }

    pub(super) fn python_tick(&mut self, py: Python<'_>, i: usize, t: f64) -> PyResult<()> {
        let touches = self.touches[i];
        self.enter_python(py, t, touches)?;
        let r = self.ticks[i].bind(py).call1((t,));
        self.leave_python(touches);
        r?;
        self.counts.python[i] += 1;
        Ok(())
    }

    /// Node `i`'s tick at `t` on its fast path; false: not in its steady state now.
    pub(super) fn fast_tick(&mut self, py: Python<'_>, i: usize, t: f64) -> PyResult<bool> {
        if !self.own_tick[i] {
            return Ok(false);
        }
        match self.kinds[i] {
            Kind::Python => Ok(false),
            Kind::Bridge => {
                let ready = match (self.bridge.as_mut(), self.plant.as_mut()) {
                    (Some(b), Some(p)) => b.ready(py)? && p.sync_ready(py)?,
                    _ => false,
                };
                if !ready {
                    return Ok(false);
                }
                let (b, p) = (self.bridge.as_mut().unwrap(), self.plant.as_mut().unwrap());
                let out = b.tick(py, t, p, self.leptrino.as_ref())?;
                if let Some((truth, touches)) = out.truth {
                    // The ground-truth sample and its sink (the logger): Python's.
                    self.enter_python(py, t, touches)?;
                    let r = truth.bind(py).call0();
                    self.leave_python(touches);
                    r?;
                }
                Ok(true)
            }
            Kind::Bank => {
                let Some(b) = self.bank.as_mut() else {
                    return Ok(false);
                };
                if !b.ready(py)? {
                    return Ok(false);
                }
                b.tick(py, t)?;
                Ok(true)
            }
            Kind::Spinal => {
                let Some(s) = self.spinal.as_mut() else {
                    return Ok(false);
                };
                if !s.ready(py, t)? {
                    return Ok(false);
                }
                self.spinal_tick(py, t)?;
                Ok(true)
            }
            Kind::Leptrino => {
                let Some(l) = self.leptrino.as_mut() else {
                    return Ok(false);
                };
                if !l.ready(py)? {
                    return Ok(false);
                }
                l.tick(py, t)
            }
        }
    }

    /// The Spinal part's tick at `t` (its `ready` said yes), with the mirror's Python
    /// continuation when the part leaves one.
    pub(super) fn spinal_tick(&mut self, py: Python<'_>, t: f64) -> PyResult<()> {
        let Some(s) = self.spinal.as_mut() else {
            return Ok(());
        };
        let tick = s.tick(py, t)?;
        if matches!(tick, SpinalTick::Done) {
            return Ok(());
        }
        // The mirror's continuation of this tick (it reads and changes only the mirror:
        // its part is written back first).
        self.enter_python(py, t, SPINAL)?;
        let s = self.spinal.as_ref().unwrap();
        let r = match tick {
            SpinalTick::Done => Ok(()),
            SpinalTick::Finish(now_ms) => s.finish(py, now_ms),
            SpinalTick::FinishStep(now_ms, tail) => s.finish_step(py, now_ms, tail),
            SpinalTick::FinishPublish(now_ms) => s.finish_publish(py, now_ms),
        };
        self.leave_python(SPINAL);
        r
    }

    /// Node `i`, the Spinal mirror, at a ms its part cannot run from its plan: the mirror
    /// receives in Python (`receive_tick`) and the rest of the ms runs here when the new
    /// plan allows it, else in Python. True: the rest ran here.
    pub(super) fn spinal_receive_tick(
        &mut self,
        py: Python<'_>,
        i: usize,
        t: f64,
    ) -> PyResult<bool> {
        fn part(k: &mut LockstepKernel) -> PyResult<&mut SpinalFast> {
            k.spinal.as_mut().ok_or_else(|| {
                pyo3::exceptions::PyRuntimeError::new_err("kernel: no Spinal part attached")
            })
        }
        let touches = self.touches[i];
        self.enter_python(py, t, touches)?;
        let r = part(self).and_then(|s| s.receive_tick(py, t));
        self.leave_python(touches);
        let Some(plan) = r? else {
            return Ok(false); // the whole tick ran in Python
        };
        let s = part(self)?;
        s.load_plan(plan)?;
        if s.ready(py, t)? {
            s.counts.receive_then_kernel += 1;
            self.spinal_tick(py, t)?;
            return Ok(true);
        }
        self.enter_python(py, t, touches)?;
        let r = part(self).and_then(|s| s.receive_rest(py, t));
        self.leave_python(touches);
        r?;
        Ok(false)
    }

    pub(super) fn physics_step(&mut self, py: Python<'_>, t: f64) -> PyResult<()> {
        let Some(physics) = self.physics.as_ref().map(|p| p.clone_ref(py)) else {
            return Ok(());
        };
        if let Some(p) = self.plant.as_mut() {
            if p.step_ready(py)? {
                p.step(py)?;
                self.physics_fast += 1;
                return Ok(());
            }
        }
        self.enter_python(py, t, PLANT)?;
        let r = physics.bind(py).call1((1,));
        self.leave_python(PLANT);
        r?;
        self.physics_python += 1;
        Ok(())
    }

    pub(super) fn run_inner(&mut self, py: Python<'_>, n: i64) -> PyResult<()> {
        let cycle = self.schedule.len();
        for _ in 0..n {
            let k = self.k;
            let t = k as f64 * self.dt;
            let slot = usize::try_from(k).unwrap_or(0) % cycle;
            let mut stop = false;
            for j in 0..self.schedule[slot].len() {
                let i = self.schedule[slot][j];
                let t0 = self.profile.then(std::time::Instant::now);
                if self.fast_tick(py, i, t)? {
                    self.counts.fast[i] += 1;
                    if let Some(t0) = t0 {
                        self.counts.fast_ns[i] += elapsed_ns(t0);
                    }
                } else if self.kinds[i] == Kind::Spinal && self.own_tick[i] && self.spinal.is_some()
                {
                    // received in Python; the rest here (fast) or there (python)
                    let rest_here = self.spinal_receive_tick(py, i, t)?;
                    if rest_here {
                        self.counts.fast[i] += 1;
                    } else {
                        self.counts.python[i] += 1;
                    }
                    if let Some(t0) = t0 {
                        let ns = elapsed_ns(t0);
                        if rest_here {
                            self.counts.fast_ns[i] += ns;
                        } else {
                            self.counts.python_ns[i] += ns;
                        }
                    }
                    stop |= self.stop.get().get();
                } else {
                    self.python_tick(py, i, t)?;
                    if let Some(t0) = t0 {
                        self.counts.python_ns[i] += elapsed_ns(t0);
                    }
                    stop |= self.stop.get().get();
                }
            }
            let t0 = self.profile.then(std::time::Instant::now);
            self.physics_step(py, t)?;
            if let Some(t0) = t0 {
                self.counts.physics_ns += elapsed_ns(t0);
            }
            self.k = k + 1;
            if stop {
                break;
            }
        }
        Ok(())
    }
}
