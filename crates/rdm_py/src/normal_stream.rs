//! `NormalStreamCore`: `rdm_core::sim::normal_stream::NormalStream` over a numpy
//! `Generator` (its `normal(0.0, 1.0, chunk)` refills it), the one owner of a sensor noise
//! model's normals (`rdm.plant.sensors`; the lockstep kernel's bridge takes from the same
//! object).

use numpy::{PyArray1, PyArrayMethods};
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use rdm_core::sim::normal_stream::NormalStream;

/// Largest take of the sensor models (an IMU sample's 9).
const MAX_TAKE: usize = 9;

/// Standard normals of one numpy generator, drawn `chunk` at a time.
#[pyclass(module = "rdm._rdm")]
pub struct NormalStreamCore {
    rng: Py<PyAny>,
    inner: NormalStream,
}

impl NormalStreamCore {
    /// Fill `out` with the next normals.
    pub(crate) fn take_into(&mut self, py: Python<'_>, out: &mut [f64]) -> PyResult<()> {
        let rng = self.rng.bind(py);
        self.inner.take(
            out,
            |buf, chunk| {
                let a = rng.call_method1(pyo3::intern!(py, "normal"), (0.0, 1.0, chunk))?;
                let a = a.cast::<PyArray1<f64>>()?.readonly();
                buf.extend_from_slice(a.as_slice()?);
                Ok(())
            },
            || PyRuntimeError::new_err("NormalStreamCore: the generator gave no values"),
        )
    }
}

#[pymethods]
impl NormalStreamCore {
    /// The stream of `rng` (a numpy `Generator`, from now on the stream's), `chunk` per draw.
    #[new]
    #[pyo3(signature = (rng, chunk = 1024))]
    fn new(rng: Py<PyAny>, chunk: usize) -> PyResult<Self> {
        if chunk == 0 {
            return Err(PyValueError::new_err(
                "NormalStreamCore: chunk must be >= 1",
            ));
        }
        Ok(NormalStreamCore {
            rng,
            inner: NormalStream::new(chunk, MAX_TAKE),
        })
    }

    /// The next `k` normals (what `k` more `rng.normal(0.0, 1.0)` draws would give).
    fn take(&mut self, py: Python<'_>, k: usize) -> PyResult<Vec<f64>> {
        let mut out = vec![0.0; k];
        self.take_into(py, &mut out)?;
        Ok(out)
    }

    /// Normals taken so far.
    #[getter]
    fn taken(&self) -> u64 {
        self.inner.taken()
    }

    /// Values drawn per refill.
    #[getter]
    fn chunk(&self) -> usize {
        self.inner.chunk()
    }
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<NormalStreamCore>()?;
    Ok(())
}
