//! The time-index records of one capture write (`rdm.link.capture_index.TimedCaptureFile.write`):
//! the loop over a batch's marks, which in Python was ~1.9 µs per simulated ms of the
//! lockstep loop (the kernel's Spinal batches carry 5-13 marks each).

use pyo3::exceptions::{PyOverflowError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyBytes;

/// `rdm.link.capture_index.time_ns`: `round(t * 1e6) * 1000` (ties to even, as Python's
/// `round`), refused where Python's `round` or the index's int64 would refuse it.
fn time_ns(t: f64) -> PyResult<i64> {
    let us = t * 1e6;
    if us.is_nan() {
        return Err(PyValueError::new_err("cannot convert float NaN to integer"));
    }
    if us.is_infinite() {
        return Err(PyOverflowError::new_err(
            "cannot convert float infinity to integer",
        ));
    }
    let us = us.round_ties_even();
    // |us| < 2^63 / 1000: the product is an int64 (else the record could not be packed)
    if us.abs() >= 9.223_372_036_854_775e15 {
        return Err(PyOverflowError::new_err(
            "capture index: time out of the int64 ns range",
        ));
    }
    Ok(us as i64 * 1000)
}

fn push_record(out: &mut Vec<u8>, ns: i64, end: u64) {
    out.extend_from_slice(&ns.to_le_bytes());
    out.extend_from_slice(&end.to_le_bytes());
}

/// `(records, last)` of a write of `n` bytes at capture offset `start`: 16-byte records
/// (`<qQ`: time ns, end offset) for the bytes the staged marks (`(base, [(time s, end)])`)
/// cover at their times, and one for the rest at `clock()` (called only when bytes are
/// left); times never go below `last` (the previous record's), which the result carries on.
#[pyfunction]
#[pyo3(signature = (start, n, staged, clock, last))]
fn capture_index_records<'py>(
    py: Python<'py>,
    start: u64,
    n: u64,
    staged: Option<(i64, Bound<'py, PyAny>)>,
    clock: &Bound<'py, PyAny>,
    last: i64,
) -> PyResult<(Bound<'py, PyBytes>, i64)> {
    let mut out = Vec::with_capacity(64);
    let mut last = last;
    let mut done: u64 = 0;
    let (start_i, n_i) = (i128::from(start), i128::from(n));
    if let Some((base, marks)) = staged {
        for mark in marks.try_iter()? {
            let (t, end): (f64, i64) = mark?.extract()?;
            let stop = i128::from(base) + i128::from(end) - start_i; // the mark's end in data
            if stop <= i128::from(done) {
                continue; // bytes written before, or a mark that does not advance
            }
            if !t.is_finite() {
                break; // no time to give: the clock's
            }
            // 0 < stop; done <= n fits u64
            done = if stop < n_i { stop as u64 } else { n };
            last = last.max(time_ns(t)?);
            push_record(&mut out, last, start + done);
            if done == n {
                break;
            }
        }
    }
    if done < n {
        last = last.max(time_ns(clock.call0()?.extract()?)?);
        push_record(&mut out, last, start + n);
    }
    Ok((PyBytes::new(py, &out), last))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(capture_index_records, m)?)?;
    Ok(())
}
