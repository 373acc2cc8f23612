//! The rosserial frame scanner and frame builder (`rdm_core::firmware::rosserial_frame`):
//! `rosserial_scan` scans `rdm.protocol.rosserial.framing.FrameParser`'s whole buffer in one
//! call; `rosserial_frame` is `framing.encode_frame`, the one frame builder of the project.

use pyo3::create_exception;
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyByteArray, PyBytes, PyInt, PyList, PyMemoryView};
use rdm_core::firmware::rosserial_frame::{next_candidate, seal_frame, Step, FRAME_OVERHEAD};

use crate::errors::RdmError;

create_exception!(
    _rdm,
    RosserialFrameError,
    RdmError,
    "A rosserial frame that cannot be built or scanned (topic id, payload type or length, \
     max_payload out of range); the message names the argument and the rule."
);

/// What one scan found; see `rosserial_scan`.
type ScanResult<'py> = (Bound<'py, PyList>, usize, usize, bool, bool, bool);

/// `value` as a non-negative integer limit: a Python `int` (not a `bool`) >= 0; any size
/// above `usize::MAX` saturates (no length field reaches it).
fn max_payload_of(value: &Bound<'_, PyAny>) -> PyResult<usize> {
    let rule = || {
        RosserialFrameError::new_err(format!(
            "max_payload {} is not an integer >= 0",
            value
                .repr()
                .map_or_else(|_| "?".to_owned(), |r| r.to_string())
        ))
    };
    if value.is_instance_of::<PyBool>() || !value.is_instance_of::<PyInt>() {
        return Err(rule());
    }
    if let Ok(n) = value.extract::<usize>() {
        return Ok(n);
    }
    // an int outside usize: huge (saturate) or negative (refused)
    if value.lt(0).unwrap_or(true) {
        Err(rule())
    } else {
        Ok(usize::MAX)
    }
}

/// Scan `buf` from `pos` as the receiver's loop does (the caller handles the frame timer and
/// the buffer). `base` is the stream offset of `buf[0]`; `max_payload` any `int >= 0`.
///
/// Returns `(events, pos, frames, clean, broke, reset)`: `events` in stream order, a good
/// frame as `(topic_id, payload, offset)`, anything else as `(kind, offset, data)` with kind
/// `"skip"` or the reject reason; `pos` the first byte not consumed; `frames` good frames;
/// `clean` no event but good frames; `broke` the scan stopped on an incomplete candidate;
/// `reset` at least one candidate was completed (the frame timer restarts).
/// Raises `RosserialFrameError` for a `max_payload` that is not an `int >= 0`.
#[pyfunction]
#[pyo3(signature = (buf, pos, base, max_payload, rescan))]
fn rosserial_scan<'py>(
    py: Python<'py>,
    buf: &Bound<'py, PyByteArray>,
    pos: usize,
    base: i64,
    max_payload: &Bound<'py, PyAny>,
    rescan: bool,
) -> PyResult<ScanResult<'py>> {
    let max_payload = max_payload_of(max_payload)?;
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

/// The one rosserial v2 frame of `payload` (`bytes`, `bytearray` or `memoryview`) on topic
/// `topic_id`: `FF FE len_lo len_hi len_chk topic_lo topic_hi payload msg_chk`.
/// Raises `RosserialFrameError` naming the rule for a topic id that is not an int in
/// 0..65535, a payload of another type, or one longer than the uint16 length field.
#[pyfunction]
fn rosserial_frame<'py>(
    py: Python<'py>,
    topic_id: &Bound<'py, PyAny>,
    payload: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyBytes>> {
    let topic = topic_of(topic_id)?;
    if let Ok(bytes) = payload.cast::<PyBytes>() {
        return frame_of(py, topic, bytes.as_bytes());
    }
    if let Ok(array) = payload.cast::<PyByteArray>() {
        return frame_of(py, topic, &array.to_vec());
    }
    if payload.is_instance_of::<PyMemoryView>() {
        let copy = py.get_type::<PyBytes>().call1((payload,))?;
        return frame_of(py, topic, copy.cast::<PyBytes>()?.as_bytes());
    }
    let kind = payload
        .get_type()
        .name()
        .map_or_else(|_| "?".to_owned(), |n| n.to_string());
    Err(RosserialFrameError::new_err(format!(
        "payload of type {kind} is not bytes, bytearray or memoryview"
    )))
}

/// `topic_id` as the frame's uint16 topic field.
fn topic_of(topic_id: &Bound<'_, PyAny>) -> PyResult<u16> {
    let text = || {
        topic_id
            .repr()
            .map_or_else(|_| "?".to_owned(), |r| r.to_string())
    };
    if topic_id.is_instance_of::<PyBool>() || !topic_id.is_instance_of::<PyInt>() {
        return Err(RosserialFrameError::new_err(format!(
            "topic_id {} is not an integer",
            text()
        )));
    }
    topic_id
        .extract::<u16>()
        .map_err(|_| RosserialFrameError::new_err(format!("topic_id {} outside 0..65535", text())))
}

/// The frame of `payload` on `topic`.
fn frame_of<'py>(py: Python<'py>, topic: u16, payload: &[u8]) -> PyResult<Bound<'py, PyBytes>> {
    let n = payload.len();
    if u16::try_from(n).is_err() {
        return Err(RosserialFrameError::new_err(format!(
            "payload of {n} bytes does not fit the uint16 length field"
        )));
    }
    PyBytes::new_with(py, n + FRAME_OVERHEAD, |frame| {
        if let Some(body) = frame.get_mut(7..7 + n) {
            body.copy_from_slice(payload);
        }
        seal_frame(topic, frame);
        Ok(())
    })
}

/// Add the scanner, the frame builder and their error type to the module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add(
        "RosserialFrameError",
        m.py().get_type::<RosserialFrameError>(),
    )?;
    m.add_function(wrap_pyfunction!(rosserial_scan, m)?)?;
    m.add_function(wrap_pyfunction!(rosserial_frame, m)?)?;
    Ok(())
}
