//! The Leptrino sensor's streaming tick (`LeptrinoSensorNode.tick` while no host command is
//! waiting) on its stream state, `LeptrinoStreamCore`, which the node shares. Frames wait in
//! that state and go to the UART in one `write_marked` call before any Python code runs.

use pyo3::exceptions::PyOSError;
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyList};

use crate::leptrino_sensor::LeptrinoStreamCore;

pub(crate) struct LeptrinoFast {
    stream: Py<LeptrinoStreamCore>,
    /// `idle()`: the node's UART is an open in-process pipe with no host bytes waiting
    /// (`rdm.nodes.lockstep_kernel`); asked again after Python code ran.
    idle: Py<PyAny>,
    /// `write_marked(data, marks) -> int` of the node's UART.
    write: Py<PyAny>,
    ready: Option<bool>,
}

impl LeptrinoFast {
    pub(crate) fn new(stream: Py<LeptrinoStreamCore>, idle: Py<PyAny>, write: Py<PyAny>) -> Self {
        LeptrinoFast {
            stream,
            idle,
            write,
            ready: None,
        }
    }

    pub(crate) fn invalidate(&mut self) {
        self.ready = None;
    }

    /// Whether the tick can run here now.
    pub(crate) fn ready(&mut self, py: Python<'_>) -> PyResult<bool> {
        if let Some(r) = self.ready {
            return Ok(r);
        }
        let r = self.idle.bind(py).call0()?.is_truthy()?;
        self.ready = Some(r);
        Ok(r)
    }

    /// The bridge's wrench sample into the sensor (clipped or refused and counted there).
    pub(crate) fn set_wrench(&self, py: Python<'_>, w: [f64; 6]) {
        self.stream.bind(py).borrow_mut().inner.set_wrench(&w);
    }

    /// The streaming tick at `now` (requires `ready`); false when the frame cannot be
    /// encoded (the caller runs the Python tick, which raises).
    pub(crate) fn tick(&mut self, py: Python<'_>, now: f64) -> PyResult<bool> {
        Ok(self
            .stream
            .bind(py)
            .borrow_mut()
            .inner
            .stream_tick(now)
            .is_ok())
    }

    /// Write the pending frames to the UART (an `OSError` is a write of nothing).
    pub(crate) fn flush(&mut self, py: Python<'_>) -> PyResult<()> {
        let stream = self.stream.bind(py);
        let (data, marks) = {
            let s = stream.borrow();
            let (data, marks) = s.inner.pending();
            if data.is_empty() {
                return Ok(());
            }
            (PyBytes::new(py, data), PyList::new(py, marks)?)
        };
        let written = match self.write.bind(py).call1((&data, marks)) {
            Ok(n) => n.extract::<usize>()?,
            Err(e) if e.is_instance_of::<PyOSError>(py) => 0,
            Err(e) => return Err(e),
        };
        stream.borrow_mut().inner.pending_written(written);
        Ok(())
    }
}
