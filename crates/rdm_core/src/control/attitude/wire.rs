//! Wire forms of the Spinal gains and matrices: every value travels as int16 x 1000
//! (`jsk-wire-protocols.md` sec. 1.8 "Scaling used on the wire" and sec. 4).
//!
//! The PC multiplies by 1000 and stores into int16 (a C++ implicit conversion: truncation
//! toward zero); Spinal multiplies by 0.001. [`clamp_gain`] is the PC-side `clampGain` that
//! keeps the P and D columns inside the int16 range before publishing.

use crate::control::gains::GainSet;
use crate::MAX_ROTORS;

/// Largest gain magnitude that fits an int16 in thousandths (`clampGain` threshold).
pub const MAX_WIRE_GAIN: f64 = 32.767;

/// One `spinal/RollPitchYawTerm` of `rpy/gain`: per-rotor gains x 1000.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RollPitchYawTermWire {
    pub roll_p: i16,
    pub roll_i: i16,
    pub roll_d: i16,
    pub pitch_p: i16,
    pub pitch_i: i16,
    pub pitch_d: i16,
    pub yaw_d: i16,
}

impl RollPitchYawTermWire {
    /// The seven fields in wire order.
    pub fn to_array(&self) -> [i16; 7] {
        [
            self.roll_p,
            self.roll_i,
            self.roll_d,
            self.pitch_p,
            self.pitch_i,
            self.pitch_d,
            self.yaw_d,
        ]
    }

    /// From the seven fields in wire order.
    pub fn from_array(v: [i16; 7]) -> Self {
        Self {
            roll_p: v[0],
            roll_i: v[1],
            roll_d: v[2],
            pitch_p: v[3],
            pitch_i: v[4],
            pitch_d: v[5],
            yaw_d: v[6],
        }
    }
}

/// A value that cannot be put on the wire.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct WireValueError {
    /// The field at fault.
    pub field: &'static str,
}

impl core::fmt::Display for WireValueError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "{}: not finite", self.field)
    }
}

impl std::error::Error for WireValueError {}

/// `value * 1000` truncated toward zero and saturated to the int16 range. The PC's C++
/// conversion is undefined outside that range; saturation is the safe reading of it.
pub fn to_wire(value: f64, field: &'static str) -> Result<i16, WireValueError> {
    if !value.is_finite() {
        return Err(WireValueError { field });
    }
    let scaled = (value * 1000.0).trunc();
    Ok(scaled.clamp(f64::from(i16::MIN), f64::from(i16::MAX)) as i16)
}

/// `value * 0.001` as Spinal reads it (in f64; the firmware uses `0.001f` in f32).
pub fn from_wire(value: i16) -> f64 {
    f64::from(value) * 0.001
}

/// The `rpy/gain` form of a gain set: roll p/i/d, pitch p/i/d and yaw d of every rotor
/// (all [`MAX_ROTORS`] entries; the message carries the first `motor_num`).
pub fn gains_to_wire(
    gains: &GainSet,
) -> Result<[RollPitchYawTermWire; MAX_ROTORS], WireValueError> {
    let mut out = [RollPitchYawTermWire::default(); MAX_ROTORS];
    for (wire, g) in out.iter_mut().zip(gains.iter()) {
        *wire = RollPitchYawTermWire {
            roll_p: to_wire(g.roll.p, "roll.p")?,
            roll_i: to_wire(g.roll.i, "roll.i")?,
            roll_d: to_wire(g.roll.d, "roll.d")?,
            pitch_p: to_wire(g.pitch.p, "pitch.p")?,
            pitch_i: to_wire(g.pitch.i, "pitch.i")?,
            pitch_d: to_wire(g.pitch.d, "pitch.d")?,
            yaw_d: to_wire(g.yaw.d, "yaw.d")?,
        };
    }
    Ok(out)
}

/// The gain set Spinal reconstructs from `rpy/gain` (yaw P/I and z stay zero: the PC
/// applies them). At most [`MAX_ROTORS`] terms are read; the rotors past them stay zero.
pub fn gains_from_wire(wire: &[RollPitchYawTermWire]) -> GainSet {
    let mut gains = GainSet::default();
    for (g, w) in gains.iter_mut().zip(wire.iter()) {
        g.roll.p = from_wire(w.roll_p);
        g.roll.i = from_wire(w.roll_i);
        g.roll.d = from_wire(w.roll_d);
        g.pitch.p = from_wire(w.pitch_p);
        g.pitch.i = from_wire(w.pitch_i);
        g.pitch.d = from_wire(w.pitch_d);
        g.yaw.d = from_wire(w.yaw_d);
    }
    gains
}

/// PC-side `clampGain` (`under_actuated_lqi_controller.cpp`): each of the roll-p, roll-d,
/// pitch-p, pitch-d and yaw-d columns whose largest |gain| over the rotors exceeds 32.767 is
/// scaled by `32.767 / max` as a whole. I gains, yaw P/I and z are left as they are.
/// Returns whether anything was scaled.
pub fn clamp_gain(gains: &mut GainSet) -> bool {
    type Column = fn(&mut crate::control::gains::RotorGains) -> &mut f64;
    let columns: [Column; 5] = [
        |g| &mut g.roll.p,
        |g| &mut g.roll.d,
        |g| &mut g.pitch.p,
        |g| &mut g.pitch.d,
        |g| &mut g.yaw.d,
    ];
    let mut scaled = false;
    for column in columns {
        let max = gains
            .iter_mut()
            .map(|g| column(g).abs())
            .fold(0.0_f64, f64::max);
        if max > MAX_WIRE_GAIN {
            let scale = MAX_WIRE_GAIN / max;
            for g in gains.iter_mut() {
                *column(g) *= scale;
            }
            scaled = true;
        }
    }
    scaled
}

/// Inertia from the `int16[6]` wire form (xx, yy, zz, xy, yz, xz, x 1000), kg m^2,
/// as a symmetric matrix.
pub fn inertia_from_wire(wire: &[i16; 6]) -> nalgebra::Matrix3<f64> {
    inertia_matrix(&wire.map(from_wire))
}

/// The symmetric inertia matrix of (xx, yy, zz, xy, yz, xz).
pub fn inertia_matrix(c: &[f64; 6]) -> nalgebra::Matrix3<f64> {
    nalgebra::Matrix3::new(c[0], c[3], c[5], c[3], c[1], c[4], c[5], c[4], c[2])
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Golden values written out by hand: `static_cast<int16_t>(value * 1000)` of the PC's
    /// C++ truncates toward zero, so 1.9999 goes out as 1999 (rounding would give 2000).
    #[test]
    fn to_wire_truncates_toward_zero() {
        let golden: [(f64, i16); 10] = [
            (0.0019, 1),
            (-0.0019, -1),
            (1.9999, 1999),
            (-1.9999, -1999),
            (1.2348, 1234),
            (-7.9996, -7999),
            (0.0009, 0),
            (-0.0009, 0),
            (32.7679, 32767),
            (-40.0, -32768),
        ];
        for (value, wire) in golden {
            assert_eq!(to_wire(value, "v"), Ok(wire), "{value}");
        }
        assert_eq!(
            to_wire(f64::NAN, "roll.p"),
            Err(WireValueError { field: "roll.p" })
        );
        assert_eq!(from_wire(-1999), -1.999);
    }
}
