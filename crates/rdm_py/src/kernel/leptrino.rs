//! The Leptrino foot-sensor mirror's streaming tick (`LeptrinoSensorNode.tick` while no host
//! command is waiting) and its `set_wrench_values` for samples inside the rated limits.
//! Frames go to a buffer written to the UART in one call before Python code runs.

use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyList, PyTuple};
use rdm_core::sim::leptrino_stream::encode_force_frame;

use super::attr::read_plan;

/// Plan of `LeptrinoSensorNode.kernel_plan()`.
struct Plan {
    streaming: bool,
    limits: [f64; 6],
    rated: [f64; 6],
    temperature: i64,
    sensor_no: i64,
}

pub(crate) struct LeptrinoFast {
    node: Py<PyAny>,
    plan: Option<Plan>,
    loaded: bool,
    /// The wrench of the last `set_wrench` here, and whether it is newer than `frame`.
    wrench: [f64; 6],
    wrench_new: bool,
    frame: Vec<u8>,
    frame_valid: bool,
    /// Frames not yet written and their count, and each frame's (tick time s, end in `out`)
    /// for the capture's time index (`TappedLink.write_marked`).
    out: Vec<u8>,
    frames: i64,
    marks: Vec<(f64, usize)>,
    dirty: bool,
}

impl LeptrinoFast {
    /// The Leptrino sensor node.
    pub(crate) fn node<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        self.node.bind(py).clone()
    }

    pub(crate) fn new(node: &Bound<'_, PyAny>) -> Self {
        LeptrinoFast {
            node: node.clone().unbind(),
            plan: None,
            loaded: false,
            wrench: [0.0; 6],
            wrench_new: false,
            frame: Vec::with_capacity(64),
            frame_valid: false,
            out: Vec::with_capacity(4096),
            frames: 0,
            marks: Vec::with_capacity(64),
            dirty: false,
        }
    }

    pub(crate) fn invalidate(&mut self) {
        self.loaded = false;
    }

    fn ensure_loaded(&mut self, py: Python<'_>) -> PyResult<()> {
        if self.loaded {
            return Ok(());
        }
        self.plan = None;
        self.frame_valid = false;
        self.wrench_new = false;
        if let Some(t) = read_plan(self.node.bind(py))? {
            let wrench: [f64; 6] = t.get_item(5)?.extract()?;
            let frame = t.get_item(6)?;
            self.wrench = wrench;
            if !frame.is_none() {
                self.frame.clear();
                self.frame
                    .extend_from_slice(frame.cast::<PyBytes>()?.as_bytes());
                self.frame_valid = true;
            }
            self.plan = Some(Plan {
                streaming: t.get_item(0)?.extract()?,
                limits: t.get_item(1)?.extract()?,
                rated: t.get_item(2)?.extract()?,
                temperature: t.get_item(3)?.extract()?,
                sensor_no: t.get_item(4)?.extract()?,
            });
        }
        self.loaded = true;
        Ok(())
    }

    /// Whether the tick can run here now.
    pub(crate) fn ready(&mut self, py: Python<'_>) -> PyResult<bool> {
        self.ensure_loaded(py)?;
        Ok(self.plan.is_some())
    }

    /// `set_wrench_values` of a sample inside the limits (true); false: not taken (outside
    /// the limits, non-finite, or no plan), the caller runs the Python method.
    pub(crate) fn set_wrench(&mut self, py: Python<'_>, w: [f64; 6]) -> PyResult<bool> {
        self.ensure_loaded(py)?;
        let Some(plan) = &self.plan else {
            return Ok(false);
        };
        // The node's chained comparisons: NaN fails them.
        let inside = w
            .iter()
            .zip(plan.limits.iter())
            .all(|(v, l)| -l <= *v && *v <= *l);
        if !inside {
            return Ok(false);
        }
        self.wrench = w;
        self.wrench_new = true;
        self.dirty = true;
        Ok(true)
    }

    /// The streaming tick at `now` (requires `ready`): one sample frame while streaming; false
    /// when the frame cannot be encoded here (the caller runs the Python tick).
    pub(crate) fn tick(&mut self, py: Python<'_>, now: f64) -> PyResult<bool> {
        self.ensure_loaded(py)?;
        let Some(plan) = &self.plan else {
            return Ok(false);
        };
        if !plan.streaming {
            return Ok(true); // no command waiting, not streaming: the tick does nothing
        }
        if self.wrench_new || !self.frame_valid {
            match encode_force_frame(
                &self.wrench,
                &plan.rated,
                plan.temperature,
                0,
                plan.sensor_no,
                0,
            ) {
                Ok(f) => {
                    self.frame.clear();
                    self.frame.extend_from_slice(f.as_bytes());
                    self.frame_valid = true;
                    self.wrench_new = false;
                }
                Err(_) => return Ok(false),
            }
        }
        self.out.extend_from_slice(&self.frame);
        self.marks.push((now, self.out.len()));
        self.frames += 1;
        self.dirty = true;
        Ok(true)
    }

    /// Write the frames and the wrench back (`LeptrinoSensorNode.kernel_commit`).
    pub(crate) fn flush(&mut self, py: Python<'_>) -> PyResult<()> {
        if !self.dirty {
            return Ok(());
        }
        if self.plan.is_none() {
            self.dirty = false;
            return Ok(());
        }
        let wrench = PyTuple::new(py, self.wrench)?;
        let frame = if self.frame_valid && !self.wrench_new {
            Some(PyBytes::new(py, &self.frame))
        } else {
            None
        };
        let data = PyBytes::new(py, &self.out);
        let marks = PyList::new(py, &self.marks)?;
        self.node
            .bind(py)
            .call_method1("kernel_commit", (data, self.frames, wrench, frame, marks))?;
        self.out.clear();
        self.marks.clear();
        self.frames = 0;
        self.dirty = false;
        Ok(())
    }
}
