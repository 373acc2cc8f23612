//! python-can `Message` -> core `RxFrame`, shared by the Neuron bank and the CAN master bindings.

use pyo3::intern;
use pyo3::prelude::*;
use rdm_core::firmware::neuron_tx::{RxFrame, FLAG_ERROR, FLAG_EXTENDED, FLAG_FD, FLAG_REMOTE};

/// The frame a python-can message carries: id, the four frame-type flags, payload (a message
/// whose `data` is not bytes-like is taken as empty, which the cores count as a DLC error).
pub(crate) fn rx_frame_of(py: Python<'_>, m: &Bound<'_, PyAny>) -> PyResult<RxFrame> {
    let id: u32 = m.getattr(intern!(py, "arbitration_id"))?.extract()?;
    let mut flags = 0u8;
    for (attr, flag) in [
        (intern!(py, "is_extended_id"), FLAG_EXTENDED),
        (intern!(py, "is_remote_frame"), FLAG_REMOTE),
        (intern!(py, "is_error_frame"), FLAG_ERROR),
        (intern!(py, "is_fd"), FLAG_FD),
    ] {
        if m.getattr(attr)?.is_truthy()? {
            flags |= flag;
        }
    }
    let data: Vec<u8> = m
        .getattr(intern!(py, "data"))?
        .extract()
        .unwrap_or_default();
    Ok(RxFrame::new(id, flags, &data))
}
