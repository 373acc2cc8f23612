//! `LeptrinoStreamCore`: `rdm_core::sim::leptrino_sensor::LeptrinoStream`, the one owner of a
//! simulated Leptrino sensor's stream state (`rdm.nodes.leptrino_sensor` and the lockstep
//! kernel both call it).

use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyInt};
use rdm_core::sim::leptrino_sensor::{FieldRange, LeptrinoStream};

/// The stream state of one simulated Leptrino sensor.
#[pyclass(module = "rdm._rdm")]
pub struct LeptrinoStreamCore {
    pub(crate) inner: LeptrinoStream,
}

fn range_error(e: FieldRange, value: &Bound<'_, PyAny>) -> PyErr {
    match e {
        FieldRange::Temperature => PyValueError::new_err(format!(
            "LeptrinoSensorNode: temperature {value} must be an int in -32768..32767"
        )),
        FieldRange::SensorNo => PyValueError::new_err(format!(
            "LeptrinoSensorNode: sensor_no {value} must be an int in 0..254"
        )),
    }
}

/// `value` as an exact Python int (no bool, no float), else the field's range error.
fn int_of(value: &Bound<'_, PyAny>, field: FieldRange) -> PyResult<i64> {
    if !value.is_exact_instance_of::<PyInt>() {
        return Err(range_error(field, value));
    }
    value
        .extract::<i64>()
        .map_err(|_| range_error(field, value))
}

#[pymethods]
impl LeptrinoStreamCore {
    /// A sensor of `rated` capacity (N, N m) at `temperature` (int16) answering to
    /// `sensor_no` (0..254), not streaming, measuring zero.
    #[new]
    fn new(
        rated: [f64; 6],
        temperature: &Bound<'_, PyAny>,
        sensor_no: &Bound<'_, PyAny>,
    ) -> PyResult<Self> {
        let t = int_of(temperature, FieldRange::Temperature)?;
        let n = int_of(sensor_no, FieldRange::SensorNo)?;
        let inner = LeptrinoStream::new(rated, t, 0).map_err(|e| range_error(e, temperature))?;
        let mut s = LeptrinoStreamCore { inner };
        s.inner
            .set_sensor_no(n)
            .map_err(|e| range_error(e, sensor_no))?;
        Ok(s)
    }

    #[getter]
    fn streaming(&self) -> bool {
        self.inner.streaming()
    }

    #[setter]
    fn set_streaming(&mut self, on: bool) {
        self.inner.set_streaming(on);
    }

    #[getter]
    fn temperature(&self) -> i64 {
        self.inner.temperature()
    }

    #[setter]
    fn set_temperature(&mut self, value: &Bound<'_, PyAny>) -> PyResult<()> {
        let t = int_of(value, FieldRange::Temperature)?;
        self.inner
            .set_temperature(t)
            .map_err(|e| range_error(e, value))
    }

    #[getter]
    fn sensor_no(&self) -> i64 {
        self.inner.sensor_no()
    }

    #[setter]
    fn set_sensor_no(&mut self, value: &Bound<'_, PyAny>) -> PyResult<()> {
        let n = int_of(value, FieldRange::SensorNo)?;
        self.inner
            .set_sensor_no(n)
            .map_err(|e| range_error(e, value))
    }

    /// The wrench the sensor measures now (Fx, Fy, Fz, Mx, My, Mz).
    #[getter]
    fn wrench(&self) -> [f64; 6] {
        self.inner.wrench()
    }

    /// Highest magnitude per axis its counts can say (`32767 * rated / 10000`).
    #[getter]
    fn limits(&self) -> [f64; 6] {
        self.inner.limits()
    }

    /// The wrench from now on: clipped to the limits (counted as saturated), or refused
    /// when not six values or not finite (counted as bad).
    fn set_wrench(&mut self, values: Vec<f64>) {
        self.inner.set_wrench(&values);
    }

    /// The sample frame of the present wrench, temperature and sensor number.
    fn sample_frame<'py>(&mut self, py: Python<'py>) -> PyResult<Bound<'py, PyBytes>> {
        match self.inner.sample_frame() {
            Ok(f) => Ok(PyBytes::new(py, f)),
            Err(e) => Err(PyValueError::new_err(format!(
                "LeptrinoSensorNode: the sample frame cannot be encoded ({e:?})"
            ))),
        }
    }

    /// A write of `length` bytes holding `frames` frames of which the UART took `written`.
    #[pyo3(signature = (length, written, frames = 1))]
    fn count_write(&mut self, length: usize, written: usize, frames: u64) {
        self.inner.count_write(length, written, frames);
    }

    #[getter]
    fn saturated_samples(&self) -> u64 {
        self.inner.saturated_samples()
    }

    #[getter]
    fn bad_wrench(&self) -> u64 {
        self.inner.bad_wrench()
    }

    #[getter]
    fn frames_sent(&self) -> u64 {
        self.inner.frames_sent()
    }

    #[getter]
    fn bytes_dropped(&self) -> u64 {
        self.inner.bytes_dropped()
    }

    #[getter]
    fn tx_short(&self) -> u64 {
        self.inner.tx_short()
    }
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<LeptrinoStreamCore>()?;
    Ok(())
}
