//! Eq. (49) reduced to the thrusts alone: the equality rows of eq. (38) are eliminated and
//! the cost of eq. (37) is turned into `½‖y‖²`, ready for [`super::active_set`].
//!
//! The scaled problem of [`super::qp`] is `min ½ xᵀPx` s.t. rows 0-3 `A x = b` (eq. 38) and
//! rows 4-28 `A x ≤ b` (eqs. 39-48), `x = [λ/s; w/s]`. In each equality row `k` the only
//! `w` entry is `A_{k,w_k} ≠ 0` (`−1` if controlled, `+1` if not, before row scaling), so
//!
//! `w_k = (b_k − A_{k,λ} λ) / A_{k,w_k}`
//!
//! exactly. Substituting into every inequality row leaves rows in `λ` only. `P` is
//! `diag(N)/max N` on `λ` and 0 on `w`, with `N > 0` (validated), so the reduced problem is
//! strictly convex: `y_i = √P_ii λ_i/s` makes the Hessian the identity. No regularisation is
//! needed; the solution is unique, and `w` follows from `λ` through eq. (38).

use nalgebra::Vector4;

use super::active_set::DualActiveSet;
use super::dims::{N_ROWS, N_VARS, N_ZERO_ROWS};
use crate::PERCH_ROTORS;

/// Inequality rows of the reduced problem (rows 4-28 of the full one, same order).
pub const REDUCED_ROWS: usize = N_ROWS - N_ZERO_ROWS;

/// `w = w_offset + w_gain x_λ` (scaled units) from the eliminated eq. (38), and the map
/// `x_λ,i = y_i / √P_ii` back from the solver's coordinates.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Elimination {
    w_offset: [f64; 4],
    w_gain: [[f64; PERCH_ROTORS]; 4],
    inv_sqrt_cost: [f64; PERCH_ROTORS],
}

impl Elimination {
    /// Scaled thrusts `λ/s` from the solver's `y`.
    pub fn thrust(&self, y: &Vector4<f64>) -> [f64; PERCH_ROTORS] {
        let mut x = [0.0; PERCH_ROTORS];
        for (i, xi) in x.iter_mut().enumerate() {
            *xi = y[i] * self.inv_sqrt_cost[i];
        }
        x
    }

    /// Scaled `W_foot,t / s` implied by eq. (38) for scaled thrusts `x`.
    pub fn foot_wrench(&self, x: &[f64; PERCH_ROTORS]) -> [f64; 4] {
        let mut w = self.w_offset;
        for (wk, gain) in w.iter_mut().zip(self.w_gain.iter()) {
            for (g, xi) in gain.iter().zip(x.iter()) {
                *wk += g * xi;
            }
        }
        w
    }
}

/// Load the reduced rows of `(a, b)` into `solver` for the cost diagonal `cost` (`P_ii` on
/// the thrusts). `None` if an equality row has no `w` coefficient or `cost` is not > 0
/// (neither happens for data built by `PerchQp`, but nothing here may panic).
pub fn load(
    solver: &mut DualActiveSet<REDUCED_ROWS>,
    a: &[[f64; N_VARS]; N_ROWS],
    b: &[f64],
    cost: &[f64; PERCH_ROTORS],
) -> Option<Elimination> {
    if b.len() != N_ROWS {
        return None;
    }
    let mut elim = Elimination {
        w_offset: [0.0; 4],
        w_gain: [[0.0; PERCH_ROTORS]; 4],
        inv_sqrt_cost: [0.0; PERCH_ROTORS],
    };
    for (inv, c) in elim.inv_sqrt_cost.iter_mut().zip(cost.iter()) {
        if !(c.is_finite() && *c > 0.0) {
            return None;
        }
        *inv = 1.0 / c.sqrt();
    }
    for (k, (row, rhs)) in a.iter().zip(b.iter()).enumerate().take(N_ZERO_ROWS) {
        let pivot = row[PERCH_ROTORS + k];
        if !(pivot.is_finite() && pivot != 0.0) {
            return None;
        }
        elim.w_offset[k] = rhs / pivot;
        for (g, coef) in elim.w_gain[k].iter_mut().zip(row.iter()) {
            *g = -coef / pivot;
        }
    }
    solver.clear_rows();
    for (r, (row, rhs)) in a.iter().zip(b.iter()).enumerate().skip(N_ZERO_ROWS) {
        // row·[x_λ; w] ≤ rhs with w = w_offset + w_gain x_λ.
        let mut coef = [0.0; PERCH_ROTORS];
        coef.copy_from_slice(&row[..PERCH_ROTORS]);
        let mut bound = *rhs;
        for k in 0..4 {
            let a_w = row[PERCH_ROTORS + k];
            if a_w != 0.0 {
                bound -= a_w * elim.w_offset[k];
                for (c, g) in coef.iter_mut().zip(elim.w_gain[k].iter()) {
                    *c += a_w * g;
                }
            }
        }
        // In y: Σ coef_i y_i/√P_ii ≤ bound, i.e. normalᵀy ≥ −bound with normal = −coef/√P.
        let normal = Vector4::from_fn(|i, _| -coef[i] * elim.inv_sqrt_cost[i]);
        solver.set_row(r - N_ZERO_ROWS, normal, -bound);
    }
    Some(elim)
}
