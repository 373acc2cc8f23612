//! The lockstep loop's inner work: the fast parts' boundaries (flush before Python runs,
//! invalidate after), one millisecond's node ticks, barriers and physics step, the pacing,
//! and `run`'s loop.

use super::*;

impl LockstepKernel {
    /// Every attached fast part with its mask bit.
    /// (The plant has none: its state is the plant's own Rust cores.)
    pub(super) fn parts(&mut self) -> [(u8, Option<&mut dyn Part>); 4] {
        [
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

    /// Node `i`'s tick at `t` on its fast path; false: not in its steady state now.
    pub(super) fn fast_tick(&mut self, py: Python<'_>, i: usize, t: f64) -> PyResult<bool> {
        if !self.own_tick[i] {
            return Ok(false);
        }
        match self.kinds[i] {
            Kind::Python => Ok(false),
            Kind::Bridge => {
                let ready = match (self.bridge.as_mut(), self.plant.as_mut()) {
                    (Some(b), Some(p)) => b.ready(py)? && p.step_ready(py),
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
            if p.step_ready(py) {
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

    /// After the nodes of the tick at `t`: every barrier's `settle()` (Python code that may
    /// read anything: every part written back first).
    fn settle(&mut self, py: Python<'_>, t: f64) -> PyResult<()> {
        if self.barriers.is_empty() {
            return Ok(());
        }
        let t0 = self.profile.then(std::time::Instant::now);
        self.enter_python(py, t, ALL)?;
        let mut r = Ok(());
        for b in &self.barriers {
            r = b.bind(py).call0().map(|_| ());
            if r.is_err() {
                break;
            }
        }
        self.leave_python(ALL);
        if let Some(t0) = t0 {
            self.counts.barriers_ns += elapsed_ns(t0);
        }
        r
    }

    /// After the tick at `t` of a paced run: sleep while ahead of the real-time factor, then
    /// the progress report when one is due (both may run Python code: every part written
    /// back first).
    fn pace(&mut self, py: Python<'_>, t: f64) -> PyResult<()> {
        let sim = self.k as f64 * self.dt;
        if let Some(seconds) = self.pacing.ahead(py, sim)? {
            self.enter_python(py, t, ALL)?;
            let r = self.pacing.sleep(py, seconds);
            self.leave_python(ALL);
            r?;
        }
        if self.pacing.report_due(sim) {
            self.enter_python(py, t, ALL)?;
            let r = self.pacing.report(py, sim, self.k);
            self.leave_python(ALL);
            r?;
        }
        Ok(())
    }

    /// Node `i`'s tick at `t`: its fast path when it is in its steady state, else its own
    /// Python tick (for the Spinal mirror: received in Python, the rest here or there).
    fn node_tick(&mut self, py: Python<'_>, i: usize, t: f64) -> PyResult<()> {
        let t0 = self.profile.then(std::time::Instant::now);
        let fast = if self.fast_tick(py, i, t)? {
            true
        } else if self.kinds[i] == Kind::Spinal && self.own_tick[i] && self.spinal.is_some() {
            self.spinal_receive_tick(py, i, t)?
        } else {
            let touches = self.touches[i];
            self.enter_python(py, t, touches)?;
            let r = self.ticks[i].bind(py).call1((t,));
            self.leave_python(touches);
            r?;
            false
        };
        let (count, ns) = if fast {
            (&mut self.counts.fast, &mut self.counts.fast_ns)
        } else {
            (&mut self.counts.python, &mut self.counts.python_ns)
        };
        count[i] += 1;
        if let Some(t0) = t0 {
            ns[i] += elapsed_ns(t0);
        }
        Ok(())
    }

    /// `n` base ticks from `k` (fewer when the stop request is set during one): the due
    /// nodes in order, the barriers, the physics step, and with `paced` the pacing and
    /// progress. Allocates nothing per tick.
    pub(super) fn run_inner(&mut self, py: Python<'_>, n: i64, paced: bool) -> PyResult<()> {
        for _ in 0..n {
            let k = self.k;
            let t = k as f64 * self.dt;
            let due = self.schedule.select(k);
            for j in 0..due {
                let i = self.schedule.due(j);
                self.node_tick(py, i, t)?;
            }
            self.settle(py, t)?;
            let t0 = self.profile.then(std::time::Instant::now);
            self.physics_step(py, t)?;
            if let Some(t0) = t0 {
                self.counts.physics_ns += elapsed_ns(t0);
            }
            self.k = k + 1;
            self.counter.get().set(self.k);
            if paced {
                self.pace(py, t)?;
            }
            if self.stop.get().get() {
                break;
            }
        }
        Ok(())
    }
}
