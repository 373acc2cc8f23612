//! The rosserial frame scanner (`rdm_core::firmware::rosserial_frame`) for
//! `rdm.protocol.rosserial.framing.FrameParser`: one call scans the parser's whole buffer;
//! and the frame builder of a payload for the PC side's publish path.

use pyo3::prelude::*;
use pyo3::types::{PyByteArray, PyBytes, PyList};
use rdm_core::firmware::rosserial_frame::{next_candidate, seal_frame, Step, FRAME_OVERHEAD};

/// What one scan found; see `rosserial_scan`.
type ScanResult<'py> = (Bound<'py, PyList>, usize, usize, bool, bool, bool);

/// Scan `buf` from `pos` as the reference parser's loop does (the caller handles the frame
/// timer and the buffer). `base` is the stream offset of `buf[0]`.
///
/// Returns `(events, pos, frames, clean, broke, reset)`: `events` in stream order, a good
/// frame as `(topic_id, payload, offset)`, anything else as `(kind, offset, data)` with kind
/// `"skip"` or the reject reason; `pos` the first byte not consumed; `frames` good frames;
/// `clean` no event but good frames; `broke` the scan stopped on an incomplete candidate;
/// `reset` at least one candidate was completed (the frame timer restarts).
#[pyfunction]
#[pyo3(signature = (buf, pos, base, max_payload, rescan))]
fn rosserial_scan<'py>(
    py: Python<'py>,
    buf: &Bound<'py, PyByteArray>,
    pos: usize,
    base: i64,
    max_payload: usize,
    rescan: bool,
) -> PyResult<ScanResult<'py>> {
    let data = buf.to_vec(); // a copy: no Python code can change it while we read
    let events = PyList::empty(py);
    let end = data.len();
    let (mut pos, mut frames, mut clean, mut broke, mut reset) = (pos, 0usize, true, false, false);
    let offset = |p: usize| base + i64::try_from(p).unwrap_or(i64::MAX);
    while pos < end {
        match next_candidate(&data, pos, max_payload) {
            Step::Skip { stop } => {
                let skipped = data.get(pos..stop).unwrap_or(&[]);
                events.append(("skip", offset(pos), PyBytes::new(py, skipped)))?;
                clean = false;
                pos = stop;
            }
            Step::NeedMore => {
                broke = true;
                break;
            }
            Step::Good {
                topic,
                payload_start,
                len,
            } => {
                let payload = data.get(payload_start..payload_start + len).unwrap_or(&[]);
                events.append((topic, PyBytes::new(py, payload), offset(pos)))?;
                frames += 1;
                reset = true;
                pos += len + FRAME_OVERHEAD;
            }
            Step::Bad { reason, used } => {
                let examined = data.get(pos..pos + used).unwrap_or(&[]);
                events.append((reason.name(), offset(pos), PyBytes::new(py, examined)))?;
                clean = false;
                reset = true;
                pos += if rescan { 1 } else { used };
            }
        }
    }
    Ok((events, pos, frames, clean, broke, reset))
}

/// Add the scanner to the module.
/// `framing.encode_frame(topic_id, payload)` for a `bytes` payload: the same frame, or None
/// (nothing built) when the topic id or the length does not fit its `u16` field or
/// `payload` is not exactly `bytes` (`encode_frame` then converts or raises).
#[pyfunction]
fn rosserial_frame<'py>(
    py: Python<'py>,
    topic_id: &Bound<'py, PyAny>,
    payload: &Bound<'py, PyAny>,
) -> Option<Bound<'py, PyBytes>> {
    let topic: u16 = topic_id.extract().ok()?;
    let payload = payload.cast_exact::<PyBytes>().ok()?.as_bytes();
    let n = payload.len();
    u16::try_from(n).ok()?;
    PyBytes::new_with(py, n + FRAME_OVERHEAD, |frame| {
        frame[7..7 + n].copy_from_slice(payload);
        seal_frame(topic, frame);
        Ok(())
    })
    .ok()
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(rosserial_scan, m)?)?;
    m.add_function(wrap_pyfunction!(rosserial_frame, m)?)?;
    Ok(())
}
