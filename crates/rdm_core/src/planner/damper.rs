//! The velocity damper shared by every constraint (Faverjon-Tournassoud, the paper's
//! [55]; eqs. 59-60, 62-63, 66-67): a quantity at distance `d` from its limit may approach
//! it by at most `gain (d - d_F) / (d_R - d_F)` per step. At d_F it may not approach at all;
//! below d_F the bound turns negative and pushes the quantity back out.

use super::config::DamperParams;

/// Largest allowed decrease of the distance `d` in one step (eqs. 66, 67 form: linear in
/// `d`, not capped, so far from the limit the row is loose).
pub fn allowed_approach(d: f64, p: &DamperParams) -> f64 {
    let span = (p.restricted - p.forbidden).max(1e-12);
    p.gain * (d - p.forbidden) / span
}

/// Step bound of eqs. (59)-(60): `step_max` scaled down inside the restricted range.
pub fn state_step_bound(d: f64, step_max: f64, p: &DamperParams) -> f64 {
    if d < p.restricted {
        let span = (p.restricted - p.forbidden).max(1e-12);
        step_max * (d - p.forbidden) / span
    } else {
        step_max
    }
}
