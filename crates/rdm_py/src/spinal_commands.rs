//! Spinal's steady command frames in one call: the PC's `four_axes/command`, `rpy/gain`,
//! `p_matrix_pseudo_inverse_inertia`, `desire_coordinate` and `servo/target_states`, decoded
//! from their rosserial payloads and applied to the controller and the CAN master with the
//! calls the Spinal mirror's message handlers make (`SpinalCommands._on_four_axis_command`,
//! ...).
//!
//! Why: the PC sends five or six such frames every 40 Hz tick; in Python each one costs a
//! decode, a route and a core call (~12 us). Here the whole run costs one call.

use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyList, PyTuple};

use crate::attitude::{wire_term_rows, PySpinalStep};
use rdm_core::firmware::can_master::{WORD_VALUE_MAX, WORD_VALUE_MIN};

use crate::can_master::CanMaster;

/// What a subscriber slot's frames are (the `kinds` table, one byte per subscriber index).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kind {
    /// `spinal/FourAxisCommand`: float32[3] angles, float32[] base_thrust.
    FourAxis = 1,
    /// `spinal/RollPitchYawTerms`: RollPitchYawTerm[] (7 x int16 each).
    Gains = 2,
    /// `spinal/PMatrixPseudoInverseWithInertia`: unit[] (3 x int16 each), int16[6].
    PinvInertia = 3,
    /// `spinal/DesireCoord`: 3 x float32.
    Desire = 4,
    /// `spinal/ServoControlCmd`: uint8[] index, int16[] angles.
    ServoTargets = 5,
}

impl Kind {
    fn from_code(code: u8) -> Option<Kind> {
        Some(match code {
            1 => Kind::FourAxis,
            2 => Kind::Gains,
            3 => Kind::PinvInertia,
            4 => Kind::Desire,
            5 => Kind::ServoTargets,
            _ => return None,
        })
    }
}

/// Little-endian reader over one payload; every read checks the length.
struct Payload<'a> {
    bytes: &'a [u8],
    pos: usize,
}

impl<'a> Payload<'a> {
    fn take(&mut self, n: usize) -> Option<&'a [u8]> {
        let end = self.pos.checked_add(n)?;
        let out = self.bytes.get(self.pos..end)?;
        self.pos = end;
        Some(out)
    }

    fn f32(&mut self) -> Option<f64> {
        Some(f64::from(f32::from_le_bytes(
            self.take(4)?.try_into().ok()?,
        )))
    }

    fn i16(&mut self) -> Option<i16> {
        Some(i16::from_le_bytes(self.take(2)?.try_into().ok()?))
    }

    /// A rosserial array length (uint32) whose `item_size`-byte items all fit.
    fn count(&mut self, item_size: usize) -> Option<usize> {
        let n = u32::from_le_bytes(self.take(4)?.try_into().ok()?) as usize;
        let rest = self.bytes.len() - self.pos;
        (n.checked_mul(item_size)? <= rest).then_some(n)
    }

    /// Everything read: the codec's decode takes no trailing byte.
    fn done(&self) -> bool {
        self.pos == self.bytes.len()
    }
}

/// A decoded command, ready for its core call.
enum Command {
    FourAxis([f64; 3], Vec<f64>),
    Gains(Vec<[i64; 7]>),
    PinvInertia(Vec<[i16; 3]>, [i16; 6]),
    Desire(f64, f64, f64),
    ServoTargets(Vec<u8>, Vec<i16>),
}

/// The message the codec decodes from `bytes`, or None when it would not (wrong length,
/// trailing bytes): the Python path then decides as before.
fn decode(kind: Kind, bytes: &[u8]) -> Option<Command> {
    let mut p = Payload { bytes, pos: 0 };
    let command = match kind {
        Kind::FourAxis => {
            let angles = [p.f32()?, p.f32()?, p.f32()?];
            let n = p.count(4)?;
            let base = (0..n).map(|_| p.f32()).collect::<Option<Vec<_>>>()?;
            Command::FourAxis(angles, base)
        }
        Kind::Gains => {
            let n = p.count(14)?;
            let mut rows = Vec::with_capacity(n);
            for _ in 0..n {
                let mut row = [0i64; 7];
                for v in &mut row {
                    *v = i64::from(p.i16()?);
                }
                rows.push(row);
            }
            Command::Gains(rows)
        }
        Kind::PinvInertia => {
            let n = p.count(6)?;
            let rows = (0..n)
                .map(|_| Some([p.i16()?, p.i16()?, p.i16()?]))
                .collect::<Option<Vec<_>>>()?;
            let mut inertia = [0i16; 6];
            for v in &mut inertia {
                *v = p.i16()?;
            }
            Command::PinvInertia(rows, inertia)
        }
        Kind::Desire => Command::Desire(p.f32()?, p.f32()?, p.f32()?),
        Kind::ServoTargets => {
            let n = p.count(1)?;
            let index = p.take(n)?.to_vec();
            let m = p.count(2)?;
            let angles = (0..m).map(|_| p.i16()).collect::<Option<Vec<_>>>()?;
            Command::ServoTargets(index, angles)
        }
    };
    p.done().then_some(command)
}

/// The `(slave, servo)` pairs of `index` in the master's servo order, when
/// `ServoBridge.target_states_values` would accept them all: as many indices as angles,
/// at least one, every index a servo and every angle a servo word. None otherwise.
fn servo_targets(master: &CanMaster, index: &[u8], angles: &[i16]) -> Option<Vec<(u8, u8, i32)>> {
    if index.len() != angles.len() || index.is_empty() {
        return None;
    }
    index
        .iter()
        .zip(angles)
        .map(|(&i, &value)| {
            let (slave, servo) = master.servo_key_iter().nth(usize::from(i))?;
            let value = i32::from(value);
            if !(WORD_VALUE_MIN..=WORD_VALUE_MAX).contains(&value) {
                return None;
            }
            Some((slave, u8::try_from(servo).ok()?, value))
        })
        .collect()
}

/// Applies `command` as the mirror's message handler does. Ok(false): the call declines
/// (nothing applied); Err: the exception its core call raises.
fn apply(
    command: Command,
    core: &mut PySpinalStep,
    master: Option<&mut CanMaster>,
    now_s: f64,
) -> PyResult<bool> {
    let ctrl = core.controller_mut();
    match command {
        Command::FourAxis(angles, base) => ctrl
            .four_axis_command(angles, &base, now_s)
            .map_err(crate::attitude::rejected)?,
        Command::Gains(rows) => ctrl
            .set_gains_wire(&wire_term_rows(&rows)?)
            .map_err(crate::attitude::rejected)?,
        Command::PinvInertia(rows, inertia) => ctrl
            .set_pinv_inertia_wire(&rows, inertia)
            .map_err(crate::attitude::rejected)?,
        Command::Desire(roll, pitch, yaw) => ctrl
            .set_desire_coordinate(roll, pitch, yaw)
            .map_err(crate::attitude::rejected)?,
        Command::ServoTargets(index, angles) => {
            let Some(master) = master else {
                return Ok(false);
            };
            let Some(targets) = servo_targets(master, &index, &angles) else {
                return Ok(false);
            };
            master.set_targets(&targets)?;
        }
    }
    Ok(true)
}

/// Applies the leading run of `items` (the parser's good frames, `(topic_id, payload,
/// offset)`) that are steady commands, in order, as `SpinalMirror._route` would.
///
/// `kinds[topic_id - first_user_id]` is the subscriber's kind code (0: not one of these).
/// `master` is the CAN master's core when `servo/target_states` may be applied (the servo
/// bridge's one-call path and a running master), else None.
///
/// Returns `(n, error)`: the first `n` items were applied (each counts as received). With
/// `error`, item `n` raised it from its core call (the caller routes the failure; that item
/// is done too). Without, item `n` (if any) is one this call does not take: a reserved id,
/// another topic, a payload the codec's fast layouts would refuse, a servo target the bridge's
/// one-call path would refuse, or a borrowed core. Nothing of item `n` was applied then.
#[pyfunction]
#[pyo3(signature = (items, kinds, first_user_id, core, master, now_s))]
fn spinal_apply_commands<'py>(
    items: &Bound<'py, PyList>,
    kinds: &[u8],
    first_user_id: i64,
    core: &Bound<'py, PySpinalStep>,
    master: Option<&Bound<'py, CanMaster>>,
    now_s: f64,
) -> (usize, Option<PyErr>) {
    let Ok(mut core) = core.try_borrow_mut() else {
        return (0, None);
    };
    let mut master = match master.map(|m| m.try_borrow_mut()) {
        Some(Ok(m)) => Some(m),
        Some(Err(_)) => return (0, None),
        None => None,
    };
    for (n, item) in items.iter().enumerate() {
        let Some(command) = command_of(&item, kinds, first_user_id) else {
            return (n, None);
        };
        match apply(command, &mut core, master.as_deref_mut(), now_s) {
            Ok(true) => {}
            Ok(false) => return (n, None),
            Err(e) => return (n, Some(e)),
        }
    }
    (items.len(), None)
}

/// The decoded command of one parser item, when it is a steady command frame.
fn command_of(item: &Bound<'_, PyAny>, kinds: &[u8], first_user_id: i64) -> Option<Command> {
    let item = item.cast_exact::<PyTuple>().ok()?;
    if item.len() != 3 {
        return None;
    }
    let topic_id: i64 = item.get_item(0).ok()?.extract().ok()?;
    let index = usize::try_from(topic_id.checked_sub(first_user_id)?).ok()?;
    let kind = Kind::from_code(*kinds.get(index)?)?;
    let payload = item.get_item(1).ok()?;
    let payload = payload.cast_exact::<PyBytes>().ok()?;
    decode(kind, payload.as_bytes())
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(spinal_apply_commands, m)?)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn f32s(values: &[f32]) -> Vec<u8> {
        values.iter().flat_map(|v| v.to_le_bytes()).collect()
    }

    #[test]
    fn four_axis_layout_and_lengths() {
        let mut bytes = f32s(&[0.1, -0.2, 0.3]);
        bytes.extend(2u32.to_le_bytes());
        bytes.extend(f32s(&[4.5, 5.5]));
        let Some(Command::FourAxis(angles, base)) = decode(Kind::FourAxis, &bytes) else {
            panic!("not decoded");
        };
        assert_eq!(angles, [0.1f32 as f64, -0.2f32 as f64, 0.3f32 as f64]);
        assert_eq!(base, vec![4.5, 5.5]);
        // a trailing byte, a short payload, a count beyond the payload
        let mut trailing = bytes.clone();
        trailing.push(0);
        assert!(decode(Kind::FourAxis, &trailing).is_none());
        assert!(decode(Kind::FourAxis, &bytes[..bytes.len() - 1]).is_none());
        let mut huge = f32s(&[0.0, 0.0, 0.0]);
        huge.extend(u32::MAX.to_le_bytes());
        assert!(decode(Kind::FourAxis, &huge).is_none());
    }

    #[test]
    fn servo_targets_layout() {
        let mut bytes = 2u32.to_le_bytes().to_vec();
        bytes.extend([3u8, 1]);
        bytes.extend(2u32.to_le_bytes());
        bytes.extend((-5i16).to_le_bytes());
        bytes.extend(700i16.to_le_bytes());
        let Some(Command::ServoTargets(index, angles)) = decode(Kind::ServoTargets, &bytes) else {
            panic!("not decoded");
        };
        assert_eq!(index, vec![3, 1]);
        assert_eq!(angles, vec![-5, 700]);
    }

    #[test]
    fn pinv_and_gains_layouts() {
        let mut pinv = 1u32.to_le_bytes().to_vec();
        for v in [1i16, -2, 3, 10, 20, 30, 40, 50, 60] {
            pinv.extend(v.to_le_bytes());
        }
        let Some(Command::PinvInertia(rows, inertia)) = decode(Kind::PinvInertia, &pinv) else {
            panic!("not decoded");
        };
        assert_eq!(rows, vec![[1, -2, 3]]);
        assert_eq!(inertia, [10, 20, 30, 40, 50, 60]);
        let mut gains = 1u32.to_le_bytes().to_vec();
        for v in [1i16, 2, 3, 4, 5, 6, -7] {
            gains.extend(v.to_le_bytes());
        }
        let Some(Command::Gains(rows)) = decode(Kind::Gains, &gains) else {
            panic!("not decoded");
        };
        assert_eq!(rows, vec![[1, 2, 3, 4, 5, 6, -7]]);
        assert!(decode(Kind::Gains, &gains[..gains.len() - 2]).is_none());
    }
}
