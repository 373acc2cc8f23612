//! The thrust of a failed tick (moved toward the bounds at the rate limit) and the clip of a
//! solved thrust into the rate box and the bounds (eqs. 45-48).

use crate::PERCH_ROTORS;

/// The command of a failed tick: move the previous thrust toward `[λ_min, λ_max]` by at most
/// `δλ_perch` (eq. 48), then clip to `[λ_min, max(λ_min, λ_max)]` (eqs. 45-47). The bounds
/// win over the rate limit, so the result is always inside the thrust limits and finite.
pub fn safe_thrust(
    previous: &[f64; PERCH_ROTORS],
    thrust_max: &[f64; PERCH_ROTORS],
    rate_limit: &[f64; PERCH_ROTORS],
) -> [f64; PERCH_ROTORS] {
    let mut out = [0.0; PERCH_ROTORS];
    for i in 0..PERCH_ROTORS {
        let lo = 0.0;
        let hi = if thrust_max[i].is_finite() {
            thrust_max[i].max(lo)
        } else {
            lo
        };
        let prev = if previous[i].is_finite() {
            previous[i]
        } else {
            lo
        };
        let target = prev.clamp(lo, hi);
        let step = (target - prev).clamp(-rate_limit[i], rate_limit[i]);
        out[i] = (prev + step).clamp(lo, hi);
    }
    out
}

/// Clip a solved thrust into the rate box of eq. (48), then into the bounds of eq. (45).
pub(super) fn clip_to_box(
    thrust: &[f64; PERCH_ROTORS],
    previous: &[f64; PERCH_ROTORS],
    thrust_max: &[f64; PERCH_ROTORS],
    rate_limit: &[f64; PERCH_ROTORS],
) -> [f64; PERCH_ROTORS] {
    let mut out = [0.0; PERCH_ROTORS];
    for i in 0..PERCH_ROTORS {
        let hi = thrust_max[i].max(0.0);
        let rate_lo = previous[i] - rate_limit[i];
        let rate_hi = previous[i] + rate_limit[i];
        out[i] = thrust[i].max(rate_lo).min(rate_hi).clamp(0.0, hi);
    }
    out
}
