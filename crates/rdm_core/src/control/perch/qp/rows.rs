//! The problem assembly of eq. (49): which entries of `A` exist, the rows of the table in
//! the module doc written and normalised each tick, `λ_max` of eq. (47), the opened rate
//! rows of the relaxation, the wrench a thrust commands, and the checks of the input.

use nalgebra::{Matrix4, Vector4};

use super::{PerchInput, PerchQp};
use crate::PERCH_ROTORS;

const W: usize = PERCH_ROTORS; // first column of w = [F_z, M_x, M_y, M_z]
const FZ: usize = W;
const MX: usize = W + 1;
const MY: usize = W + 2;
const MZ: usize = W + 3;
const ROW_BOUND_LOW: usize = 13;
const ROW_BOUND_HIGH: usize = 17;
const ROW_RATE_HIGH: usize = 21;
const ROW_RATE_LOW: usize = 25;
/// Beyond this `‖Q̄‖·‖Q̄⁻¹ e₁‖` the allocation of eq. (47) is treated as singular.
const MAX_ALLOCATION_CONDITION: f64 = 1e10;

/// Which `(row, col)` entries of `A` exist. Fixed for the solver's life, independent of data
/// (a coefficient that is 0 now is still stored, so later updates keep the pattern).
pub(super) fn a_pattern(row: usize, col: usize) -> bool {
    match row {
        0..=3 => col < PERCH_ROTORS || col == W + row,
        4..=6 => col == FZ,
        7 | 8 => col == FZ || col == MZ,
        9 | 10 => col == FZ || col == MY,
        11 | 12 => col == FZ || col == MX,
        13..=28 => col == (row - ROW_BOUND_LOW) % PERCH_ROTORS,
        _ => false,
    }
}

impl PerchQp {
    /// `λ_max` of eq. (47) (or the flight-thrust form), `None` if `Q̄` is singular.
    pub(super) fn thrust_max(&self, input: &PerchInput) -> Option<[f64; PERCH_ROTORS]> {
        let mut out = self.params.rotor_thrust_max;
        if let Some(flight) = input.flight_thrust {
            for (o, f) in out.iter_mut().zip(flight.iter()) {
                *o -= f;
            }
            return Some(out);
        }
        // Q̄⁻¹ m g̃ with g̃ = [−g, 0, 0, 0]: minus the hover thrust.
        let e1 = Vector4::new(1.0, 0.0, 0.0, 0.0);
        let hover_per_weight = input.allocation.lu().solve(&e1)?;
        let condition = input.allocation.norm() * hover_per_weight.norm();
        if !condition.is_finite() || condition > MAX_ALLOCATION_CONDITION {
            return None;
        }
        let weight = input.mass * self.params.gravity;
        for (o, h) in out.iter_mut().zip(hover_per_weight.iter()) {
            *o -= weight * h;
        }
        out.iter().all(|v| v.is_finite()).then_some(out)
    }

    pub(super) fn perch_allocation(&self, foot_allocation: &Matrix4<f64>) -> Matrix4<f64> {
        let mut m = *foot_allocation;
        for (col, used) in self.params.perch_rotors.iter().enumerate() {
            if !used {
                m.column_mut(col).fill(0.0);
            }
        }
        m
    }

    /// Write the dense rows of the table in the module doc, normalise them and copy the
    /// pattern entries into `a_nzval` (same order as the CSC built in `new`).
    pub(super) fn fill_rows(
        &mut self,
        input: &PerchInput,
        perch_allocation: &Matrix4<f64>,
        thrust_max: &[f64; PERCH_ROTORS],
    ) {
        let p = &self.params;
        let s = self.scale;
        let a = &mut self.dense_a;
        let b = &mut self.b;
        for row in a.iter_mut() {
            row.fill(0.0);
        }
        let [fx, fy, fz, mx, my, mz] = input.foot_wrench;
        let measured = [fz, mx, my, mz];
        // Rows 0-3, eq. (38): in scaled variables the right side is divided by s.
        for k in 0..4 {
            if p.wrench_mask[k] {
                for i in 0..PERCH_ROTORS {
                    a[k][i] = perch_allocation[(k, i)];
                }
                a[k][W + k] = -1.0;
                b[k] = p.feedback_gain * (input.previous_foot_wrench[k] - measured[k]) / s;
            } else {
                a[k][W + k] = 1.0;
                b[k] = measured[k] / s;
            }
        }
        // Eq. (39).
        a[4][FZ] = -1.0;
        b[4] = -p.epsilon_z / s;
        // Eq. (40).
        a[5][FZ] = -p.mu_x;
        b[5] = -fx.abs() / s;
        a[6][FZ] = -p.mu_y;
        b[6] = -fy.abs() / s;
        // Eq. (41).
        a[7][MZ] = 1.0;
        a[7][FZ] = -p.mu_z;
        b[7] = 0.0;
        a[8][MZ] = -1.0;
        a[8][FZ] = -p.mu_z;
        b[8] = 0.0;
        // Eqs. (42)-(43): −H_x F_z ≤ F̃_x p_z − M_y ≤ H_x F_z.
        a[9][FZ] = -p.half_size_x;
        a[9][MY] = -1.0;
        b[9] = -fx * p.zmp_z / s;
        a[10][FZ] = -p.half_size_x;
        a[10][MY] = 1.0;
        b[10] = fx * p.zmp_z / s;
        // Eqs. (42), (44): −H_y F_z ≤ F̃_y p_z + M_x ≤ H_y F_z.
        a[11][FZ] = -p.half_size_y;
        a[11][MX] = 1.0;
        b[11] = -fy * p.zmp_z / s;
        a[12][FZ] = -p.half_size_y;
        a[12][MX] = -1.0;
        b[12] = fy * p.zmp_z / s;
        // Eqs. (45)-(48).
        for i in 0..PERCH_ROTORS {
            a[ROW_BOUND_LOW + i][i] = -1.0;
            b[ROW_BOUND_LOW + i] = 0.0;
            a[ROW_BOUND_HIGH + i][i] = 1.0;
            b[ROW_BOUND_HIGH + i] = thrust_max[i] / s;
            a[ROW_RATE_HIGH + i][i] = 1.0;
            b[ROW_RATE_HIGH + i] = (input.previous_thrust[i] + p.thrust_rate_limit[i]) / s;
            a[ROW_RATE_LOW + i][i] = -1.0;
            b[ROW_RATE_LOW + i] = (-input.previous_thrust[i] + p.thrust_rate_limit[i]) / s;
        }
        // Row normalisation: largest coefficient of each row becomes 1.
        for (row, rhs) in a.iter_mut().zip(b.iter_mut()) {
            let norm = row.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
            if norm > 0.0 {
                for v in row.iter_mut() {
                    *v /= norm;
                }
                *rhs /= norm;
            }
        }
        for (nz, (row, col)) in self.a_nzval.iter_mut().zip(self.a_entries.iter()) {
            *nz = a[*row][*col];
        }
    }

    /// Open the rate rows of eq. (48) so that they never bind inside the bounds of eqs.
    /// (45)-(47): `λ ≤ max(λ_max, 0) + δ` and `−λ ≤ δ` (their coefficients are ±1, so the row
    /// normalisation of `fill_rows` left them unscaled).
    pub(super) fn open_rate_rows(&mut self, thrust_max: &[f64; PERCH_ROTORS]) {
        let s = self.scale;
        let rates = self.params.thrust_rate_limit;
        for (i, (max, rate)) in thrust_max.iter().zip(rates.iter()).enumerate() {
            self.b[ROW_RATE_HIGH + i] = (max.max(0.0) + rate) / s;
            self.b[ROW_RATE_LOW + i] = rate / s;
        }
    }

    /// `W_foot,t` that `thrust` commands through eq. (38): controlled components
    /// `Q̄_perch,k λ − κ (W_t−1,k − W̃_k)`, the others the measured `W̃_k`.
    pub(super) fn commanded_wrench(
        &self,
        thrust: &[f64; PERCH_ROTORS],
        perch_allocation: &Matrix4<f64>,
        input: &PerchInput,
    ) -> [f64; 4] {
        let [_, _, fz, mx, my, mz] = input.foot_wrench;
        let measured = [fz, mx, my, mz];
        let mut out = measured;
        for (k, w) in out.iter_mut().enumerate() {
            if self.params.wrench_mask[k] {
                let produced: f64 = (0..PERCH_ROTORS)
                    .map(|i| perch_allocation[(k, i)] * thrust[i])
                    .sum();
                *w = produced
                    - self.params.feedback_gain * (input.previous_foot_wrench[k] - measured[k]);
            }
        }
        out
    }
}

pub(super) fn input_is_finite(input: &PerchInput) -> bool {
    input.foot_allocation.iter().all(|v| v.is_finite())
        && input.allocation.iter().all(|v| v.is_finite())
        && input.mass.is_finite()
        && input.foot_wrench.iter().all(|v| v.is_finite())
        && input.previous_thrust.iter().all(|v| v.is_finite())
        && input.previous_foot_wrench.iter().all(|v| v.is_finite())
        && input
            .flight_thrust
            .is_none_or(|f| f.iter().all(|v| v.is_finite()))
}

/// Smallest Cholesky pivot of the controlled rows' Gram matrix, relative to the largest row
/// norm, that [`controlled_rows_independent`] accepts.
const INDEPENDENT_PIVOT: f64 = 1e-6;

/// The controlled rows of `Q̄_perch` must be linearly independent for the merged eq. (38) to
/// equal the paper's split form (a zero row would let `W_t` absorb the feedback term).
pub(super) fn controlled_rows_independent(
    perch_allocation: &Matrix4<f64>,
    mask: &[bool; 4],
) -> bool {
    let mut rows = Matrix4::<f64>::identity();
    let mut largest = 0.0_f64;
    for (k, &controlled) in mask.iter().enumerate() {
        if controlled {
            let row = perch_allocation.row(k);
            largest = largest.max(row.norm());
            rows.set_row(k, &row);
        }
    }
    if largest == 0.0 {
        return false;
    }
    // Rows of the unmasked slots are unit vectors scaled to the same size, so the Gram
    // matrix only degenerates when the controlled rows do.
    for (k, &controlled) in mask.iter().enumerate() {
        if !controlled {
            rows.set_row(k, &(Matrix4::<f64>::identity().row(k) * largest));
        }
    }
    let gram = rows * rows.transpose();
    match gram.cholesky() {
        Some(chol) => {
            let l = chol.l();
            let min_pivot = (0..4).fold(f64::INFINITY, |m, i| m.min(l[(i, i)].abs()));
            // The Gram matrix squares the rows' condition: exactly dependent rows leave a
            // pivot of rounding size, about sqrt(eps) = 1.5e-8 of the largest row. Rows whose
            // pivot is below 1e-6 of it (a condition number above 1e6) are taken as dependent.
            min_pivot > INDEPENDENT_PIVOT * largest
        }
        None => false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exactly_dependent_controlled_rows_are_refused_at_any_scale() {
        // F_z, M_x and M_y by two perch rotors on one line: the M_y row is -0.1 x the F_z row
        // (its Gram pivot is of rounding size, 1.9e-9 of the largest row).
        let q = Matrix4::new(
            1.0, 1.0, 0.0, 0.0, //
            0.2, -0.2, 0.0, 0.0, //
            -0.1, -0.1, 0.0, 0.0, //
            0.0, 0.0, 0.0, 0.0,
        );
        for scale in [1e-3, 1.0, 1e3] {
            let q = q * scale;
            assert!(
                !controlled_rows_independent(&q, &[true, true, true, false]),
                "{scale}"
            );
            // F_z and M_x alone: orthogonal rows
            assert!(
                controlled_rows_independent(&q, &[true, true, false, false]),
                "{scale}"
            );
            // a zero row controlled
            assert!(
                !controlled_rows_independent(&q, &[true, false, false, true]),
                "{scale}"
            );
        }
    }
}
