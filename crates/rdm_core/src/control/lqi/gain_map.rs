//! Mapping of the LQI gain K onto the per-rotor [`GainSet`] Spinal consumes
//! (`jsk-wire-protocols.md` sec. 4 "Gains sent to Spinal"), and `clampGain`.

use crate::control::gains::{GainSet, PidGains, RotorGains};
use crate::control::riccati::GainMatrix;

/// Largest gain that fits the int16 x 0.001 wire format of `rpy/gain`.
pub const MAX_WIRE_GAIN: f64 = 32.767;

/// Number of integral states offset (`2m` with m = 4 axes).
const INTEGRAL_OFFSET: usize = 8;

/// (P, I, D) of one axis from K: P and D are the negated position and rate columns
/// (K multiplies `x − x_s`, the gain multiplies `x_s − x` and Spinal subtracts `Kd ω`),
/// I is the integral column as is (the integral state already integrates `x_s − x`).
fn axis_gains(k: &GainMatrix, rotor: usize, axis: usize) -> PidGains {
    PidGains {
        p: -k[(rotor, 2 * axis)],
        i: k[(rotor, INTEGRAL_OFFSET + axis)],
        d: -k[(rotor, 2 * axis + 1)],
    }
}

/// Applies the sec. 4 mapping: z = axis 0, roll = 1, pitch = 2, yaw = 3.
pub fn gain_set_from_k(k: &GainMatrix) -> GainSet {
    let mut set = GainSet::default();
    for (rotor, gains) in set.iter_mut().enumerate() {
        *gains = RotorGains {
            z: axis_gains(k, rotor, 0),
            roll: axis_gains(k, rotor, 1),
            pitch: axis_gains(k, rotor, 2),
            yaw: axis_gains(k, rotor, 3),
        };
    }
    set
}

/// Scale factors `clamp_gain` applied, one per clamped column.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClampScales {
    pub roll_p: f64,
    pub roll_d: f64,
    pub pitch_p: f64,
    pub pitch_d: f64,
    pub yaw_d: f64,
}

impl Default for ClampScales {
    fn default() -> Self {
        Self {
            roll_p: 1.0,
            roll_d: 1.0,
            pitch_p: 1.0,
            pitch_d: 1.0,
            yaw_d: 1.0,
        }
    }
}

/// Scales one column (one gain across all rotors) so its largest |gain| is at most
/// [`MAX_WIRE_GAIN`]; returns the factor (1 when nothing changed).
fn clamp_column(set: &mut GainSet, field: fn(&mut RotorGains) -> &mut f64) -> f64 {
    let mut largest = 0.0f64;
    for gains in set.iter_mut() {
        largest = largest.max(field(gains).abs());
    }
    if largest <= MAX_WIRE_GAIN {
        return 1.0;
    }
    let scale = MAX_WIRE_GAIN / largest;
    for gains in set.iter_mut() {
        *field(gains) *= scale;
    }
    scale
}

/// JSK `clampGain`: the roll-P, roll-D, pitch-P, pitch-D and yaw-D columns are each scaled
/// down (all rotors by the same factor) when their largest |gain| exceeds 32.767.
/// The I gains and the PC-side z and yaw P/I are left as they are (as in JSK).
pub fn clamp_gain(set: &mut GainSet) -> ClampScales {
    ClampScales {
        roll_p: clamp_column(set, |g| &mut g.roll.p),
        roll_d: clamp_column(set, |g| &mut g.roll.d),
        pitch_p: clamp_column(set, |g| &mut g.pitch.p),
        pitch_d: clamp_column(set, |g| &mut g.pitch.d),
        yaw_d: clamp_column(set, |g| &mut g.yaw.d),
    }
}

/// Index of the rotor with the largest positive yaw D gain (JSK `maxYawGainIndex`),
/// or `None` if no rotor has a positive yaw D gain (the zero entries past the rotor count
/// never count).
pub fn max_yaw_gain_index(set: &GainSet) -> Option<usize> {
    let mut best: Option<(usize, f64)> = None;
    for (rotor, gains) in set.iter().enumerate() {
        let d = gains.yaw.d;
        if d > 0.0 && best.is_none_or(|(_, b)| d > b) {
            best = Some((rotor, d));
        }
    }
    best.map(|(rotor, _)| rotor)
}
