//! The loop's wall clock: pacing to a real-time factor, progress reports every
//! `progress_every` simulated seconds, and the wall time of the runs. Nodes never see it.

use std::time::{Duration, Instant};

use pyo3::prelude::*;

/// The wall clock and sleep the loop paces with: the process's own (monotonic, sleeping
/// without the GIL) or Python callables a test injects.
pub(super) struct Pacing {
    epoch: Instant,
    wall: Option<Py<PyAny>>,
    sleep: Option<Py<PyAny>>,
    /// Simulated seconds per wall second to pace to (None: as fast as possible).
    speed: Option<f64>,
    /// `progress(sim_time, wall_time, ticks, real_time_factor)`.
    progress: Option<Py<PyAny>>,
    progress_every: f64,
    wall0: f64,
    sim0: f64,
    next_report: f64,
    /// Wall seconds of the paced runs so far.
    pub(super) wall_time: f64,
}

impl Pacing {
    /// `wall`/`sleep`: None for the process's own clock and sleep.
    pub(super) fn new(
        speed: Option<f64>,
        progress: Option<Py<PyAny>>,
        progress_every: f64,
        wall: Option<Py<PyAny>>,
        sleep: Option<Py<PyAny>>,
    ) -> PyResult<Self> {
        if let Some(s) = speed {
            if !(s.is_finite() && s > 0.0) {
                return Err(pyo3::exceptions::PyValueError::new_err(format!(
                    "Lockstep: speed {s} must be None or a positive number"
                )));
            }
        }
        if !(progress_every.is_finite() && progress_every > 0.0) {
            return Err(pyo3::exceptions::PyValueError::new_err(format!(
                "Lockstep: progress_every {progress_every} must be > 0"
            )));
        }
        Ok(Pacing {
            epoch: Instant::now(),
            wall,
            sleep,
            speed,
            progress,
            progress_every,
            wall0: 0.0,
            sim0: 0.0,
            next_report: 0.0,
            wall_time: 0.0,
        })
    }

    /// Wall seconds on the loop's clock.
    fn now(&self, py: Python<'_>) -> PyResult<f64> {
        match &self.wall {
            Some(f) => f.bind(py).call0()?.extract(),
            None => Ok(self.epoch.elapsed().as_secs_f64()),
        }
    }

    /// A run starts at simulated time `sim0`.
    pub(super) fn begin(&mut self, py: Python<'_>, sim0: f64) -> PyResult<()> {
        self.wall0 = self.now(py)?;
        self.sim0 = sim0;
        self.next_report = sim0 + self.progress_every;
        Ok(())
    }

    /// The run ended: its wall time added.
    pub(super) fn end(&mut self, py: Python<'_>) -> PyResult<()> {
        self.wall_time += self.now(py)? - self.wall0;
        Ok(())
    }

    /// Wall seconds the loop is ahead of `speed` after reaching simulated time `sim` (None:
    /// not paced, or not ahead). A slow tick is never made up by skipping: it slows the run.
    pub(super) fn ahead(&self, py: Python<'_>, sim: f64) -> PyResult<Option<f64>> {
        let Some(speed) = self.speed else {
            return Ok(None);
        };
        let ahead = (sim - self.sim0) / speed - (self.now(py)? - self.wall0);
        Ok((ahead > 0.0).then_some(ahead))
    }

    /// Sleep `seconds` (the process's sleep releases the GIL; a pending signal, e.g.
    /// KeyboardInterrupt, is raised after it).
    pub(super) fn sleep(&self, py: Python<'_>, seconds: f64) -> PyResult<()> {
        match &self.sleep {
            Some(f) => f.bind(py).call1((seconds,)).map(|_| ()),
            None => {
                let d = Duration::try_from_secs_f64(seconds).unwrap_or(Duration::ZERO);
                py.detach(|| std::thread::sleep(d));
                py.check_signals() // Ctrl-C during a paced run stops it here
            }
        }
    }

    /// Whether a progress report is due at simulated time `sim` (then the next one is
    /// scheduled `progress_every` later).
    pub(super) fn report_due(&mut self, sim: f64) -> bool {
        if self.progress.is_none() || sim < self.next_report - 1e-12 {
            return false;
        }
        self.next_report += self.progress_every;
        true
    }

    /// Call the progress callback at simulated time `sim` after `ticks` base ticks.
    pub(super) fn report(&self, py: Python<'_>, sim: f64, ticks: u64) -> PyResult<()> {
        let Some(progress) = &self.progress else {
            return Ok(());
        };
        let wall = self.now(py)? - self.wall0;
        let rtf = if wall > 0.0 {
            (sim - self.sim0) / wall
        } else {
            f64::INFINITY
        };
        progress.bind(py).call1((sim, wall, ticks, rtf)).map(|_| ())
    }
}
