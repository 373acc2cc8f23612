//! Dual active-set solver (Goldfarb-Idnani style) for the reduced perching QP of eq. (49).
//!
//! Problem, in the coordinates `y` built by [`super::reduced`] (identity Hessian, no linear
//! term, every usable row of unit length):
//!
//! ```text
//! minimise ½‖y‖²   subject to   n_iᵀ y ≥ e_i,   i = 0..ROWS
//! ```
//!
//! Method (written from the optimality conditions): keep an active set `A` of linearly
//! independent rows and multipliers `u ≥ 0` with `y = Σ_{j∈A} u_j n_j` and `n_jᵀ y = e_j`
//! (so `y` is the optimum of the QP restricted to `A`: dual feasible). Pick the most violated
//! row `p`; split `n_p = N_A r + z` with `z ⟂ span N_A`. Moving `y ← y + t z`,
//! `u ← u − t r`, `u_p ← t` keeps `y = N u` and raises the slack of `p` by `t ‖z‖²`:
//! - full step `t₂ = −slack_p/‖z‖²` makes `p` active;
//! - partial step `t₁ = min_{r_j>0} u_j/r_j` first drives a multiplier to zero: drop that row;
//! - `z = 0` and no `r_j > 0`: `n_p` is a non-positive combination of active rows, which
//!   proves `n_pᵀ y' ≤ n_pᵀ y < e_p` for every feasible `y'`: infeasible (Farkas).
//!
//! Each pass adds or drops one row; the cost `½‖y‖²` never decreases, which bounds the number
//! of passes in exact arithmetic; the explicit cap `max_iter` bounds it in floating point.
//! All storage is fixed-size (stack arrays); nothing allocates.

use nalgebra::Vector4;

/// Variables of the reduced problem (the four rotor thrusts).
pub const VARS: usize = 4;

/// A row is "violated" when its slack is below `−FEASIBILITY_TOL` (unit rows, `‖y‖ = O(1)`;
/// with `s = 30 N` this is 3e-9 N).
pub const FEASIBILITY_TOL: f64 = 1e-10;
/// `‖z‖` below this means `n_p` lies in the span of the active rows (degenerate/parallel rows).
const DEPENDENT_TOL: f64 = 1e-9;
/// An infeasibility proof is trusted only if the violated row misses by more than this;
/// closer calls are reported as [`ActiveSetOutcome::Unsure`] (the caller falls back).
const INFEASIBLE_MIN_GAP: f64 = 1e-6;
/// Final check (a full KKT certificate): every slack ≥ −VERIFY_TOL, every multiplier
/// ≥ −VERIFY_TOL, active rows with a multiplier hold with equality, stationarity
/// `‖y − N u‖ ≤ VERIFY_TOL`; otherwise the answer is [`ActiveSetOutcome::Unsure`].
const VERIFY_TOL: f64 = 1e-9;

/// How one active-set solve ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ActiveSetOutcome {
    /// Every row holds to `FEASIBILITY_TOL` and the multipliers are nonnegative.
    Optimal,
    /// A Farkas certificate with a gap above `INFEASIBLE_MIN_GAP`.
    Infeasible,
    /// `max_iter` passes without finishing.
    IterationLimit,
    /// Numerically doubtful (near-infeasible, failed final check, non-finite data).
    Unsure,
}

/// Orthonormal basis `Q` of the active normals (in active order) and `R` with `N_A = Q R`.
struct Factor {
    q: [Vector4<f64>; VARS],
    r: [[f64; VARS]; VARS],
    len: usize,
}

impl Factor {
    fn empty() -> Self {
        Self {
            q: [Vector4::zeros(); VARS],
            r: [[0.0; VARS]; VARS],
            len: 0,
        }
    }

    /// Split `v = Q c + z` with `z ⟂ Q` (Gram-Schmidt with one re-orthogonalisation pass).
    fn split(&self, v: &Vector4<f64>) -> ([f64; VARS], Vector4<f64>) {
        let mut c = [0.0; VARS];
        let mut z = *v;
        for _ in 0..2 {
            for (cj, qj) in c.iter_mut().zip(self.q.iter()).take(self.len) {
                let d = qj.dot(&z);
                *cj += d;
                z -= qj * d;
            }
        }
        (c, z)
    }

    /// Append `v`; false (and unchanged) if it is within `DEPENDENT_TOL` of the span.
    fn push(&mut self, v: &Vector4<f64>) -> bool {
        if self.len >= VARS {
            return false;
        }
        let (c, z) = self.split(v);
        let norm = z.norm();
        if norm.is_nan() || norm <= DEPENDENT_TOL {
            return false;
        }
        let k = self.len;
        self.q[k] = z / norm;
        for (i, ci) in c.iter().enumerate().take(k) {
            self.r[i][k] = *ci;
        }
        self.r[k][k] = norm;
        self.len += 1;
        true
    }

    /// Solve `R x = c` (upper triangular, diagonal ≥ DEPENDENT_TOL by construction).
    fn back_substitute(&self, c: &[f64; VARS]) -> [f64; VARS] {
        let mut x = [0.0; VARS];
        for i in (0..self.len).rev() {
            let mut acc = c[i];
            for (j, xj) in x.iter().enumerate().take(self.len).skip(i + 1) {
                acc -= self.r[i][j] * xj;
            }
            x[i] = acc / self.r[i][i];
        }
        x
    }

    /// Solve `Rᵀ x = c` (lower triangular).
    fn forward_substitute(&self, c: &[f64; VARS]) -> [f64; VARS] {
        let mut x = [0.0; VARS];
        for i in 0..self.len {
            let mut acc = c[i];
            for (j, xj) in x.iter().enumerate().take(i) {
                acc -= self.r[j][i] * xj;
            }
            x[i] = acc / self.r[i][i];
        }
        x
    }
}

/// Fixed-size dual active-set solver for `ROWS` inequality rows in 4 variables.
/// Remembers the last optimal active set and starts the next solve from it (warm start).
#[derive(Clone, Debug)]
pub struct DualActiveSet<const ROWS: usize> {
    normals: [Vector4<f64>; ROWS],
    offsets: [f64; ROWS],
    usable: [bool; ROWS],
    /// Largest `e_i` of a row whose normal vanished (`0 ≥ e_i` must hold).
    constant_violation: f64,
    active: [usize; VARS],
    multipliers: [f64; VARS],
    active_len: usize,
    warm: [usize; VARS],
    warm_len: usize,
    y: Vector4<f64>,
}

impl<const ROWS: usize> Default for DualActiveSet<ROWS> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const ROWS: usize> DualActiveSet<ROWS> {
    /// An empty problem (no rows usable) with no warm start.
    pub fn new() -> Self {
        Self {
            normals: [Vector4::zeros(); ROWS],
            offsets: [0.0; ROWS],
            usable: [false; ROWS],
            constant_violation: f64::NEG_INFINITY,
            active: [0; VARS],
            multipliers: [0.0; VARS],
            active_len: 0,
            warm: [0; VARS],
            warm_len: 0,
            y: Vector4::zeros(),
        }
    }

    /// Start a new problem: every row unusable until [`Self::set_row`]. Keeps the warm start.
    pub fn clear_rows(&mut self) {
        self.usable = [false; ROWS];
        self.constant_violation = f64::NEG_INFINITY;
    }

    /// Row `i`: `normalᵀ y ≥ offset`, scaled here to a unit normal. A (numerically) zero
    /// normal makes the row the constant condition `0 ≥ offset`. Out-of-range `i` is ignored.
    pub fn set_row(&mut self, i: usize, normal: Vector4<f64>, offset: f64) {
        let norm = normal.norm();
        let (Some(n), Some(e), Some(u)) = (
            self.normals.get_mut(i),
            self.offsets.get_mut(i),
            self.usable.get_mut(i),
        ) else {
            return;
        };
        // Relative to the size of the row's right-hand side and of O(1) variables.
        if norm > 1e-12 * (1.0 + offset.abs()) {
            *n = normal / norm;
            *e = offset / norm;
            *u = true;
        } else {
            *u = false;
            self.constant_violation = self.constant_violation.max(offset);
        }
    }

    /// Forget the warm start (next solve starts from `y = 0`).
    pub fn forget_warm_start(&mut self) {
        self.warm_len = 0;
    }

    /// The solution of the last [`Self::solve`] (meaningful after `Optimal`).
    pub fn solution(&self) -> Vector4<f64> {
        self.y
    }

    /// Rows active at the last solution, in the order they were added.
    pub fn active_rows(&self) -> &[usize] {
        &self.active[..self.active_len]
    }

    fn slack(&self, i: usize) -> f64 {
        self.normals[i].dot(&self.y) - self.offsets[i]
    }

    fn factor_active(&self) -> Factor {
        let mut f = Factor::empty();
        for &j in &self.active[..self.active_len] {
            // Active rows were independent when added and dropping rows keeps them so.
            f.push(&self.normals[j]);
        }
        f
    }

    fn drop_active(&mut self, k: usize) {
        for i in k..self.active_len.saturating_sub(1) {
            self.active[i] = self.active[i + 1];
            self.multipliers[i] = self.multipliers[i + 1];
        }
        self.active_len = self.active_len.saturating_sub(1);
    }

    /// Rebuild `(A, u, y)` from the remembered active set: keep independent usable rows,
    /// solve `N_Aᵀ N_A u = e_A`, drop the most negative multiplier until all are ≥ 0.
    fn warm_start(&mut self) {
        self.active_len = 0;
        let mut f = Factor::empty();
        for k in 0..self.warm_len {
            let j = self.warm[k];
            if j < ROWS && self.usable[j] && f.push(&self.normals[j]) {
                self.active[self.active_len] = j;
                self.active_len += 1;
            }
        }
        for _ in 0..=VARS {
            let f = self.factor_active();
            let mut e = [0.0; VARS];
            for (ek, &j) in e.iter_mut().zip(self.active[..self.active_len].iter()) {
                *ek = self.offsets[j];
            }
            let u = f.back_substitute(&f.forward_substitute(&e));
            let mut worst = None;
            let mut worst_value = 0.0;
            for (k, uk) in u.iter().enumerate().take(self.active_len) {
                if !uk.is_finite() || *uk < worst_value {
                    worst = Some(k);
                    worst_value = if uk.is_finite() {
                        *uk
                    } else {
                        f64::NEG_INFINITY
                    };
                }
            }
            match worst {
                Some(k) => self.drop_active(k),
                None => {
                    self.multipliers[..self.active_len].copy_from_slice(&u[..self.active_len]);
                    break;
                }
            }
        }
        self.y = Vector4::zeros();
        for k in 0..self.active_len {
            self.y += self.normals[self.active[k]] * self.multipliers[k];
        }
        if !self.y.iter().all(|v| v.is_finite()) {
            self.active_len = 0;
            self.y = Vector4::zeros();
        }
    }

    /// Solve with at most `max_iter` add/drop passes. Returns the outcome and the passes used.
    pub fn solve(&mut self, max_iter: u32) -> (ActiveSetOutcome, u32) {
        let finite = self.offsets.iter().all(|v| v.is_finite())
            && self.normals.iter().all(|n| n.iter().all(|v| v.is_finite()));
        if !finite {
            self.forget_warm_start();
            return (ActiveSetOutcome::Unsure, 0);
        }
        if self.constant_violation > INFEASIBLE_MIN_GAP {
            self.forget_warm_start();
            return (ActiveSetOutcome::Infeasible, 0);
        }
        if self.constant_violation > FEASIBILITY_TOL {
            self.forget_warm_start();
            return (ActiveSetOutcome::Unsure, 0);
        }
        self.warm_start();
        let (outcome, iterations) = self.iterate(max_iter);
        let outcome = match outcome {
            ActiveSetOutcome::Optimal if !self.verified() => ActiveSetOutcome::Unsure,
            other => other,
        };
        if outcome == ActiveSetOutcome::Optimal {
            self.warm[..self.active_len].copy_from_slice(&self.active[..self.active_len]);
            self.warm_len = self.active_len;
        } else {
            self.forget_warm_start();
        }
        (outcome, iterations)
    }

    fn most_violated(&self) -> Option<(usize, f64)> {
        let mut best: Option<(usize, f64)> = None;
        for i in 0..ROWS {
            if !self.usable[i] || self.active[..self.active_len].contains(&i) {
                continue;
            }
            let s = self.slack(i);
            if s < -FEASIBILITY_TOL && best.is_none_or(|(_, b)| s < b) {
                best = Some((i, s));
            }
        }
        best
    }

    fn iterate(&mut self, max_iter: u32) -> (ActiveSetOutcome, u32) {
        let mut iterations = 0u32;
        while let Some((p, _)) = self.most_violated() {
            let mut u_p = 0.0;
            loop {
                if iterations >= max_iter {
                    return (ActiveSetOutcome::IterationLimit, iterations);
                }
                iterations += 1;
                let f = self.factor_active();
                let n_p = self.normals[p];
                let (c, z) = f.split(&n_p);
                let r = f.back_substitute(&c);
                // Partial step: the first active multiplier to reach zero.
                let mut blocking = None;
                let mut t1 = f64::INFINITY;
                for (k, rk) in r.iter().enumerate().take(self.active_len) {
                    if *rk > 0.0 {
                        let t = self.multipliers[k] / rk;
                        if t < t1 {
                            t1 = t;
                            blocking = Some(k);
                        }
                    }
                }
                let z_norm2 = z.norm_squared();
                let slack_p = self.slack(p);
                if slack_p >= -FEASIBILITY_TOL {
                    break; // already satisfied after the previous partial step
                }
                let full_step = z_norm2.sqrt() > DEPENDENT_TOL;
                if !full_step && blocking.is_none() {
                    return if -slack_p > INFEASIBLE_MIN_GAP {
                        (ActiveSetOutcome::Infeasible, iterations)
                    } else {
                        (ActiveSetOutcome::Unsure, iterations)
                    };
                }
                let t2 = if full_step {
                    -slack_p / z_norm2
                } else {
                    f64::INFINITY
                };
                let t = t1.min(t2);
                if !t.is_finite() || t < 0.0 {
                    return (ActiveSetOutcome::Unsure, iterations);
                }
                if full_step {
                    self.y += z * t;
                }
                for (m, rk) in self
                    .multipliers
                    .iter_mut()
                    .zip(r.iter())
                    .take(self.active_len)
                {
                    *m -= t * rk;
                }
                u_p += t;
                if full_step && t2 <= t1 {
                    if self.active_len >= VARS {
                        return (ActiveSetOutcome::Unsure, iterations);
                    }
                    self.active[self.active_len] = p;
                    self.multipliers[self.active_len] = u_p;
                    self.active_len += 1;
                    break;
                }
                match blocking {
                    Some(k) => self.drop_active(k),
                    None => return (ActiveSetOutcome::Unsure, iterations),
                }
            }
        }
        (ActiveSetOutcome::Optimal, iterations)
    }

    /// Independent check of the KKT conditions at the returned point (feasibility, dual
    /// feasibility, complementarity, stationarity: together they prove optimality).
    fn verified(&self) -> bool {
        if !self.y.iter().all(|v| v.is_finite()) {
            return false;
        }
        let mut combination = Vector4::zeros();
        for k in 0..self.active_len {
            let u = self.multipliers[k];
            if u.is_nan() || u < -VERIFY_TOL {
                return false;
            }
            // Complementarity: a row carrying a multiplier must hold with equality.
            if u > VERIFY_TOL && self.slack(self.active[k]) > VERIFY_TOL {
                return false;
            }
            combination += self.normals[self.active[k]] * u;
        }
        if (combination - self.y).norm() > VERIFY_TOL * (1.0 + self.y.norm()) {
            return false;
        }
        (0..ROWS).all(|i| !self.usable[i] || self.slack(i) >= -VERIFY_TOL)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn projection_onto_a_halfspace_and_a_corner() {
        let mut s = DualActiveSet::<3>::new();
        s.clear_rows();
        s.set_row(0, Vector4::new(1.0, 0.0, 0.0, 0.0), 2.0); // y0 ≥ 2
        s.set_row(1, Vector4::new(0.0, 1.0, 1.0, 0.0), 1.0); // y1 + y2 ≥ 1
        s.set_row(2, Vector4::new(-1.0, 0.0, 0.0, 0.0), -5.0); // y0 ≤ 5
        let (outcome, _) = s.solve(20);
        assert_eq!(outcome, ActiveSetOutcome::Optimal);
        let y = s.solution();
        assert!((y - Vector4::new(2.0, 0.5, 0.5, 0.0)).norm() < 1e-12, "{y}");
    }

    #[test]
    fn contradictory_rows_are_infeasible() {
        let mut s = DualActiveSet::<2>::new();
        s.set_row(0, Vector4::new(1.0, 1.0, 0.0, 0.0), 3.0);
        s.set_row(1, Vector4::new(-1.0, -1.0, 0.0, 0.0), -1.0);
        assert_eq!(s.solve(20).0, ActiveSetOutcome::Infeasible);
    }

    /// Projection of 0 onto the polytope by enumerating every set of at most 4 rows: the
    /// optimum is the unique point `y = N_S u` with `N_Sᵀ y = e_S`, `u ≥ 0`, all rows held.
    /// `None` when no subset gives one (infeasible).
    fn brute_force(rows: &[(Vector4<f64>, f64)]) -> Option<Vector4<f64>> {
        let m = rows.len();
        for mask in 0u32..(1 << m) {
            if mask.count_ones() > 4 {
                continue;
            }
            let picked: Vec<usize> = (0..m).filter(|i| mask & (1 << i) != 0).collect();
            let n = nalgebra::DMatrix::from_fn(4, picked.len(), |r, c| rows[picked[c]].0[r]);
            let e = nalgebra::DVector::from_fn(picked.len(), |r, _| rows[picked[r]].1);
            let gram = n.transpose() * &n;
            let Some(u) = gram.clone().cholesky().map(|c| c.solve(&e)) else {
                continue;
            };
            if gram.determinant().abs() < 1e-10 || u.iter().any(|v| *v < -1e-9) {
                continue;
            }
            let y: Vector4<f64> = Vector4::from_iterator((&n * &u).iter().copied());
            let tol = 1e-9 * (1.0 + y.norm()); // far-away optima (nearly infeasible) round off
            if rows.iter().all(|(nr, er)| nr.dot(&y) - er > -tol) {
                return Some(y);
            }
        }
        None
    }

    #[test]
    fn warm_started_and_degenerate_problems_match_enumeration() {
        // Deterministic pseudo-random rows (LCG), including exact duplicates and parallels.
        let mut state = 12345u64;
        let mut next = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((state >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
        };
        let mut solver = DualActiveSet::<8>::new();
        let mut checked = 0;
        for trial in 0..200 {
            let mut rows = [(Vector4::zeros(), 0.0); 8];
            for row in rows.iter_mut() {
                *row = (Vector4::new(next(), next(), next(), next()), 0.5 * next());
            }
            rows[5] = rows[1]; // duplicate
            rows[6] = (rows[2].0 * 3.0, rows[2].1 * 3.0 - 0.01 * (trial % 3) as f64); // parallel
            solver.clear_rows();
            for (i, (n, e)) in rows.iter().enumerate() {
                solver.set_row(i, *n, *e);
            }
            let (outcome, _) = solver.solve(50); // warm start from the previous trial
            let reference = brute_force(&rows);
            match (outcome, reference) {
                (ActiveSetOutcome::Optimal, Some(r)) => {
                    let d = (solver.solution() - r).norm();
                    assert!(d < 1e-8 * (1.0 + r.norm()), "trial {trial}: {d}");
                    checked += 1;
                }
                (ActiveSetOutcome::Infeasible, None) => {}
                other => panic!(
                    "trial {trial}: {other:?} active {:?} mult {:?} y {} rows {rows:?}",
                    solver.active_rows(),
                    solver.multipliers,
                    solver.solution()
                ),
            }
        }
        assert!(checked > 50, "{checked}");
    }
}
