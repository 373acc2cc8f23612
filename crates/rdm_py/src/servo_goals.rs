//! The onboard node's servo goals and their `servo/target_states` payload in one call: what
//! `OnboardNode._send_servo_targets` does for a `ServoMap` when Spinal subscribes with
//! `spinal/ServoControlCmd` (the joint targets, the vectoring joints overwritten with the
//! last command's angles, each goal to raw ticks, the message packed). In Python that was
//! ~30 us of the 40 Hz tick (a dozen conversions, a tick per joint, a `struct` format).

use numpy::{PyArray1, PyArrayMethods};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyList};

/// Joints a goal list may have (the model's joints; more: the Python form).
const MAX_JOINTS: usize = 32;

/// `ServoMap.to_raw`: `round(zero + sign * q / scale)` (ties to even, as Python's `round` of
/// a float), saturated to int16; None for a value Python's `round` refuses (NaN, inf).
fn to_raw(zero: f64, sign: f64, scale: f64, q: f64) -> Option<i16> {
    let x = zero + sign * q / scale;
    if !x.is_finite() {
        return None;
    }
    Some(x.round_ties_even().clamp(-32768.0, 32767.0) as i16)
}

/// `(goals, payload)`: the goals `_send_servo_targets` keeps in `last_servo_goals` (the
/// first `n` of the targets, vectoring joints overwritten) and the `spinal/ServoControlCmd`
/// bytes it publishes, with `n = min(len(index), len(targets))`.
///
/// `targets` is the float64 vector of joint targets; `vectoring` the last command's
/// `(alpha, beta)` when they are written over the joints `pairs` (`(alpha joint, beta
/// joint)` per unit), else None; `zero`, `sign`, `scale` and `index` the servo map's
/// per-joint values. None, with nothing computed, for anything the Python form would treat
/// otherwise: other types or lengths, a pair outside the goals, a target or goal whose
/// ticks Python's `round` refuses, an index outside uint8 (the caller's Python form then decides, and
/// raises as before).
#[pyfunction]
#[pyo3(signature = (targets, vectoring, pairs, zero, sign, scale, index))]
#[allow(clippy::too_many_arguments)]
fn servo_target_payload<'py>(
    py: Python<'py>,
    targets: &Bound<'py, PyAny>,
    vectoring: Option<(Bound<'py, PyAny>, Bound<'py, PyAny>)>,
    pairs: &Bound<'py, PyAny>,
    zero: &Bound<'py, PyAny>,
    sign: &Bound<'py, PyAny>,
    scale: &Bound<'py, PyAny>,
    index: &Bound<'py, PyAny>,
) -> Option<(Bound<'py, PyList>, Bound<'py, PyBytes>)> {
    let zero: Vec<f64> = zero.extract().ok()?;
    let sign: Vec<f64> = sign.extract().ok()?;
    let scale: Vec<f64> = scale.extract().ok()?;
    let index: Vec<i64> = index.extract().ok()?;
    let mut base = [0.0_f64; MAX_JOINTS];
    let len = {
        let view = targets.cast::<PyArray1<f64>>().ok()?.try_readonly().ok()?;
        let values = view.as_array();
        if values.len() > MAX_JOINTS {
            return None;
        }
        for (slot, v) in base.iter_mut().zip(values.iter()) {
            *slot = *v;
        }
        values.len()
    };
    let mut q = base;
    if let Some((alpha, beta)) = vectoring {
        for (i, pair) in pairs.try_iter().ok()?.enumerate() {
            let (ja, jb): (usize, usize) = pair.ok()?.extract().ok()?;
            if ja >= len || jb >= len {
                return None;
            }
            q[ja] = alpha.get_item(i).ok()?.extract().ok()?;
            q[jb] = beta.get_item(i).ok()?.extract().ok()?;
        }
    }
    let n = index.len().min(len);
    if zero.len() < n || sign.len() < n || scale.len() < n {
        return None;
    }
    let mut payload = Vec::with_capacity(8 + 3 * n);
    payload.extend_from_slice(&(n as u32).to_le_bytes());
    for &i in &index[..n] {
        payload.push(u8::try_from(i).ok()?);
    }
    payload.extend_from_slice(&(n as u32).to_le_bytes());
    for j in 0..n {
        // the Python form converts every target before the vectoring angles replace some
        to_raw(zero[j], sign[j], scale[j], base[j])?;
        let raw = to_raw(zero[j], sign[j], scale[j], q[j])?;
        payload.extend_from_slice(&raw.to_le_bytes());
    }
    let goals = PyList::new(py, &q[..n]).ok()?;
    Some((goals, PyBytes::new(py, &payload)))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(servo_target_payload, m)?)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::to_raw;

    #[test]
    fn ticks_round_half_to_even_and_saturate() {
        assert_eq!(to_raw(0.0, 1.0, 1.0, 2.5), Some(2));
        assert_eq!(to_raw(0.0, 1.0, 1.0, 3.5), Some(4));
        assert_eq!(to_raw(0.0, -1.0, 1.0, 2.5), Some(-2));
        assert_eq!(to_raw(2048.0, 1.0, 1e-9, 1.0), Some(32767));
        assert_eq!(to_raw(2048.0, -1.0, 1e-9, 1.0), Some(-32768));
        assert_eq!(to_raw(0.0, 1.0, 1.0, f64::NAN), None);
        assert_eq!(to_raw(0.0, 1.0, 1e-300, 1e300), None);
    }
}
