//! Busy-millisecond helpers of the Spinal mirror (`rdm.nodes.spinal_mirror.SpinalMirror`):
//! the 200 Hz `spinal/Imu` frame in one call (`rdm_core::firmware::rosserial_frame::
//! imu_frame`), the 50 Hz `spinal/ServoStates` frame from the Rust CAN master's servo table,
//! and a control step's duty list without numpy. Each declines (None or False) anything the
//! Python path would treat differently; the mirror then runs that path (the reference the
//! tests compare them with).

use pyo3::prelude::*;
use pyo3::types::{PyBool, PyBytes, PyFloat, PyInt, PyList, PyTuple};
use rdm_core::firmware::rosserial_frame::{
    client_stamp, imu_frame, servo_states_frame_len, write_servo_states_frame, ImuValues,
    ServoStateValues,
};

use crate::attitude::SpinalStepOutput;
use crate::can_master::CanMaster;

/// An exact Python int (not bool, not a subclass) that fits i64.
pub(crate) fn exact_i64(v: &Bound<'_, PyAny>) -> Option<i64> {
    if v.is_exact_instance_of::<PyInt>() {
        v.extract::<i64>().ok()
    } else {
        None
    }
}

/// Three exact Python floats in a tuple or a list of length 3.
pub(crate) fn float3(v: &Bound<'_, PyAny>) -> Option<[f64; 3]> {
    let mut out = [0.0; 3];
    if let Ok(t) = v.cast_exact::<PyTuple>() {
        if t.len() != 3 {
            return None;
        }
        for (o, item) in out.iter_mut().zip(t.iter()) {
            *o = item.cast_exact::<PyFloat>().ok()?.value();
        }
    } else {
        let l = v.cast_exact::<PyList>().ok()?;
        if l.len() != 3 {
            return None;
        }
        for (o, item) in out.iter_mut().zip(l.iter()) {
            *o = item.cast_exact::<PyFloat>().ok()?.value();
        }
    }
    Some(out)
}

/// The `spinal/Imu` frame the mirror publishes at MCU tick `now_ms`, whole (header,
/// payload, checksums), or None.
///
/// `topic_id`: the `imu` publisher's id; `synced`, `sync_tick`, `sync_ns`: the
/// `ClientClock` state the stamp comes from (`ClientClock.now(now_ms)`); `acc`, `mag`: the
/// mirror's IMU sample (tuples or lists of 3 floats); `output`: the last
/// `SpinalStepOutput` (its filtered angular velocity and quaternion). The same bytes as
/// `framing.encode_frame(topic_id, imu_codec.encode(msg))`; None (nothing done) when an
/// argument is not of these exact types, a value is not finite or overflows float32, or
/// the stamp does not fit a ROS `time`.
#[pyfunction]
#[pyo3(signature = (topic_id, now_ms, synced, sync_tick, sync_ns, acc, output, mag))]
#[allow(clippy::too_many_arguments)]
fn spinal_imu_frame<'py>(
    py: Python<'py>,
    topic_id: &Bound<'py, PyAny>,
    now_ms: &Bound<'py, PyAny>,
    synced: &Bound<'py, PyAny>,
    sync_tick: &Bound<'py, PyAny>,
    sync_ns: &Bound<'py, PyAny>,
    acc: &Bound<'py, PyAny>,
    output: &Bound<'py, PyAny>,
    mag: &Bound<'py, PyAny>,
) -> Option<Bound<'py, PyBytes>> {
    let topic = u16::try_from(exact_i64(topic_id)?).ok()?;
    let now = exact_i64(now_ms)?;
    let sync = if synced.cast_exact::<PyBool>().ok()?.is_true() {
        Some((exact_i64(sync_tick)?, exact_i64(sync_ns)?))
    } else {
        None
    };
    let out = output.cast_exact::<SpinalStepOutput>().ok()?.get();
    let estimate = &out.inner.estimate;
    let values = ImuValues {
        acc: float3(acc)?,
        gyro: estimate.angular_velocity.into(),
        mag: float3(mag)?,
        quaternion: estimate.quaternion,
    };
    let frame = imu_frame(topic, client_stamp(now, sync)?, &values)?;
    Some(PyBytes::new(py, &frame))
}

/// The duty list of a control step as `SpinalMirror._step` builds it for `n` motors:
/// `[min(1.0, max(idle, d)) for d in output.duty.tolist()[:n]]` (Python's `max`/`min`
/// comparisons, so NaN gives `idle`), or None when the step has events (the Python path
/// handles them first), `n` is not in 1..=(the step's ESC outputs) or `output` is not a
/// `SpinalStepOutput`.
#[pyfunction]
fn spinal_duty_list<'py>(
    py: Python<'py>,
    output: &Bound<'py, PyAny>,
    n: &Bound<'py, PyAny>,
    idle: f64,
) -> PyResult<Option<Bound<'py, PyList>>> {
    let Some(n) = exact_i64(n).and_then(|n| usize::try_from(n).ok()) else {
        return Ok(None);
    };
    let Ok(out) = output.cast_exact::<SpinalStepOutput>() else {
        return Ok(None);
    };
    let control = &out.get().inner.control;
    if n == 0 || n > control.outputs || !control.events.is_empty() || control.events.dropped() > 0 {
        return Ok(None);
    }
    let list = PyList::empty(py);
    for &d in control.duty.iter().take(n) {
        list.append(PyFloat::new(py, clamp_duty(d, idle)))?;
    }
    Ok(Some(list))
}

/// `min(1.0, max(idle, d))` with Python's `max`/`min` (the first argument unless the second
/// compares greater / smaller: NaN gives `idle`).
pub(crate) fn clamp_duty(d: f64, idle: f64) -> f64 {
    let m = if d > idle { d } else { idle };
    if m < 1.0 {
        m
    } else {
        1.0
    }
}

/// What [`servo_states_frame_into`] did.
pub(crate) enum ServoFrame {
    /// No servo has send_data_flag: no message.
    Empty,
    /// A servo's index passes 255: the Python path decides.
    Declined,
    /// The frame, of this many bytes, was appended.
    Written(usize),
}

/// The `spinal/ServoStates` frame of `spinal_servo_states_frame` appended to `out` (no
/// allocation when `out` has the room).
pub(crate) fn servo_states_frame_into(
    core: &rdm_core::firmware::can_master::CanMaster,
    topic: u16,
    stamp: (u32, u32),
    out: &mut Vec<u8>,
) -> ServoFrame {
    let sending = || {
        core.neurons()
            .iter()
            .flat_map(|n| n.servos())
            .enumerate()
            .filter(|(_, s)| s.send_data_flag)
    };
    let mut n = 0usize;
    for (i, _) in sending() {
        if i > usize::from(u8::MAX) {
            return ServoFrame::Declined;
        }
        n += 1;
    }
    if n == 0 {
        return ServoFrame::Empty;
    }
    let servos = sending().map(|(i, s)| ServoStateValues {
        index: u8::try_from(i).unwrap_or(u8::MAX),
        angle: s.angle,
        temp: s.temperature,
        load: s.current,
        error: s.error,
    });
    let len = servo_states_frame_len(n);
    let start = out.len();
    out.resize(start + len, 0);
    if write_servo_states_frame(topic, stamp, servos, &mut out[start..]) {
        ServoFrame::Written(len)
    } else {
        out.truncate(start);
        ServoFrame::Declined
    }
}

/// The `spinal/ServoStates` frame of the servos with send_data_flag in `master`'s table
/// (a `rdm._rdm.CanMaster`; index = position in the whole table, as
/// `ServoBridge.states`), on `topic_id` with stamp `(sec, nsec)`: the bytes of
/// `encode_frame(topic_id, codec.encode(states_msg))`. None when no servo has
/// send_data_flag (no message); False (declined) when an argument is not an exact int in
/// range, `master` is not a `CanMaster`, or a reporting servo's index passes 255. The
/// caller checks that the master is running (else the table is not reported at all).
#[pyfunction]
fn spinal_servo_states_frame<'py>(
    py: Python<'py>,
    topic_id: &Bound<'py, PyAny>,
    sec: &Bound<'py, PyAny>,
    nsec: &Bound<'py, PyAny>,
    master: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyAny>> {
    let declined = PyBool::new(py, false).to_owned().into_any();
    let word = |v: &Bound<'py, PyAny>| exact_i64(v).and_then(|x| u32::try_from(x).ok());
    let (Some(topic), Some(sec), Some(nsec)) = (
        exact_i64(topic_id).and_then(|x| u16::try_from(x).ok()),
        word(sec),
        word(nsec),
    ) else {
        return Ok(declined);
    };
    let Ok(master) = master.cast_exact::<CanMaster>() else {
        return Ok(declined);
    };
    let Ok(master) = master.try_borrow() else {
        return Ok(declined);
    };
    let mut out = Vec::new();
    match servo_states_frame_into(master.core_ref(), topic, (sec, nsec), &mut out) {
        ServoFrame::Empty => Ok(py.None().into_bound(py)),
        ServoFrame::Declined => Ok(declined),
        ServoFrame::Written(_) => Ok(PyBytes::new(py, &out).into_any()),
    }
}

/// Add the helpers to the module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(spinal_imu_frame, m)?)?;
    m.add_function(wrap_pyfunction!(spinal_duty_list, m)?)?;
    m.add_function(wrap_pyfunction!(spinal_servo_states_frame, m)?)?;
    Ok(())
}
