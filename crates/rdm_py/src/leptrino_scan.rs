//! Host-side Leptrino fast scan: `rdm_core::sim::leptrino_stream::ok_sample_run` for the
//! foot sensor reader (`rdm.protocol.leptrino.LeptrinoStreamParser.feed_ok_samples`).

use pyo3::prelude::*;
use pyo3::types::PyBytes;
use rdm_core::sim::leptrino_stream::ok_sample_run;

/// `(end, count, last_start, last_payload)` of the leading run of whole OK-sample frames
/// of `data` (last_payload is None when count is 0).
#[pyfunction]
fn leptrino_ok_sample_run<'py>(
    py: Python<'py>,
    data: &[u8],
) -> (usize, usize, usize, Option<Bound<'py, PyBytes>>) {
    let run = ok_sample_run(data);
    let payload = (run.count > 0).then(|| PyBytes::new(py, &run.last_payload));
    (run.end, run.count, run.last_start, payload)
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(leptrino_ok_sample_run, m)?)?;
    Ok(())
}
