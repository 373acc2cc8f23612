//! The perching QP of eq. (49): the row builder shared by both solvers, the solver choice
//! ([`PerchSolver`]), and the safe command of a failed tick.
//!
//! Default path: [`super::reduced`] eliminates eq. (38) and [`super::active_set`] solves the
//! 4-variable problem (dense, fixed-size, warm-started). Clarabel (one solver built at setup
//! with a fixed sparsity pattern, updated in place) is the alternative
//! (`PerchSolver::Clarabel`) and the fallback when the active-set solver reaches its
//! iteration cap or is numerically unsure.
//!
//! # Formulation (see `docs/perch.md` for the derivation)
//!
//! Decision vector (8 entries, each divided by `s = max λ_rotor_max` so it is O(1)):
//! `x = [λ_perch,t (4 rotors); w_t = W_foot,t = [F_z, M_x, M_y, M_z]_t]`.
//!
//! Eq. (38) splits `λ_perch,t = λ' + λ''` with `U(Q̄_perch λ' − W_t) = 0` and
//! `U(Q̄_perch λ'' − (W_{t−1} − W̃)) = 0`. Neither half appears anywhere else, so (for
//! linearly independent controlled rows, checked every tick) the pair is equivalent to the
//! single row `U(Q̄_perch λ − W_t) = U κ (W_{t−1} − W̃)` on their sum. Uncontrolled components
//! of `W_t` are fixed to their measured value `W̃`, which is how eqs. (41), (43) and (44)
//! use `M̃` with Table VII's `U_mask = diag[1, 0, 0, 0]`.
//!
//! Cost (eq. 37): `λᵀ N λ` (`P = diag(N)/max(N)` on the thrust block, 0 on `w`; `q = 0`).
//!
//! Rows (`A x + s = b`; rows 0-3 in the zero cone, 4-28 in the nonnegative cone):
//!
//! | row | equation | constraint |
//! |---|---|---|
//! | 0-3 | (38) | controlled k: `Q̄_perch,k λ − w_k = κ (W_{t−1,k} − W̃_k)`; else `w_k = W̃_k` |
//! | 4 | (39) | `−F_z ≤ −ε_z` |
//! | 5 | (40) x | `−μ_x F_z ≤ −\|F̃_x\|` |
//! | 6 | (40) y | `−μ_y F_z ≤ −\|F̃_y\|` |
//! | 7, 8 | (41) | `±M_z − μ_z F_z ≤ 0` |
//! | 9, 10 | (42),(43) | `−H_x F_z ∓ M_y ≤ ∓F̃_x p_z` |
//! | 11, 12 | (42),(44) | `−H_y F_z ± M_x ≤ ∓F̃_y p_z` |
//! | 13-16 | (45),(46) | `−λ_i ≤ 0` |
//! | 17-20 | (45),(47) | `λ_i ≤ λ_max,i` |
//! | 21-24 | (48) | `λ_i ≤ λ_{t−1,i} + δ_i` |
//! | 25-28 | (48) | `−λ_i ≤ −λ_{t−1,i} + δ_i` |
//!
//! Every row is divided by its largest coefficient each tick (rows stay O(1) whatever the
//! data), so Clarabel's one-off equilibration is switched off.

use clarabel::algebra::CscMatrix;
use clarabel::solver::{
    DefaultSettings, DefaultSettingsBuilder, DefaultSolver, IPSolver, NonnegativeConeT,
    SolverStatus, SupportedConeT, ZeroConeT,
};
use nalgebra::{Matrix4, Vector4};

use super::active_set::{ActiveSetOutcome, DualActiveSet};
use super::dims::{N_ROWS, N_VARS, N_ZERO_ROWS};
use super::params::{ParamError, PerchParams, PerchSolver};
use super::reduced::{self, REDUCED_ROWS};
use super::status::{PerchCounters, PerchStatus};
use crate::N_ROTORS;

const W: usize = N_ROTORS; // first column of w = [F_z, M_x, M_y, M_z]
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

/// Inputs of one perching QP. All wrenches are in the foot frame at its origin, with the
/// sign of the wrench the foot applies to the surface (`F_z > 0` presses, eq. 39).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PerchInput {
    /// `Q̄_foot(q)`: rows `[F_z, M_x, M_y, M_z]` of the wrench produced at the foot origin by
    /// unit rotor thrusts (columns = rotors). The QP uses `Q̄_perch = Q̄_foot diag(perch_rotors)`.
    pub foot_allocation: Matrix4<f64>,
    /// `Q̄(q)`: rows 3-6 (`F_z, M_x, M_y, M_z`) of `Q(q)` in the CoG frame, for eq. (47).
    pub allocation: Matrix4<f64>,
    /// Robot mass `m` [kg], for eq. (47).
    pub mass: f64,
    /// Measured (filtered) foot wrench `W̃ = [F_x, F_y, F_z, M_x, M_y, M_z]`.
    pub foot_wrench: [f64; 6],
    /// `λ_perch,t−1` [N], for eq. (48).
    pub previous_thrust: [f64; N_ROTORS],
    /// `W_foot,t−1 = [F_z, M_x, M_y, M_z]` decided at the previous tick, for eq. (38).
    pub previous_foot_wrench: [f64; 4],
    /// `None`: eq. (47). `Some(λ_flight)`: bound the total thrust instead,
    /// `λ_max = λ_rotor_max − λ_flight` (eq. 20 with the flight thrust actually commanded).
    pub flight_thrust: Option<[f64; N_ROTORS]>,
}

/// Result of one perching QP. Every field is finite whatever the input.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PerchSolution {
    /// Outcome; anything but solved/almost solved/rate limited means `thrust` is the safe
    /// command.
    pub status: PerchStatus,
    /// `λ_perch,t` [N], inside `[thrust_min, thrust_max]`.
    pub thrust: [f64; N_ROTORS],
    /// `W_foot,t = [F_z, M_x, M_y, M_z]` of the solution (previous one on failure).
    pub foot_wrench: [f64; 4],
    /// ZMP `[p_x, p_y]` of eqs. (43)-(44) with `foot_wrench`'s `F_z` [m].
    pub zmp: [f64; 2],
    /// `[μ_x F_z − |F̃_x|, μ_y F_z − |F̃_y|, μ_z F_z − |M_z|]` (≥ 0 when eqs. 40-41 hold).
    pub friction_margin: [f64; 3],
    /// `[H_x − |p_x|, H_y − |p_y|]` (≥ 0 when eq. 42 holds).
    pub zmp_margin: [f64; 2],
    /// `λ_min` of eq. (46).
    pub thrust_min: [f64; N_ROTORS],
    /// `λ_max` used this tick (eq. 47 or the flight-thrust form; last valid one on failure).
    pub thrust_max: [f64; N_ROTORS],
    /// Iterations of the solver that answered: active-set add/drop passes, or Clarabel's
    /// interior-point iterations on a fallback or with `PerchSolver::Clarabel` (0 when no
    /// solver ran).
    pub iterations: u32,
    /// True when the active-set solver handed this tick over to Clarabel.
    pub fallback: bool,
}

/// Eq. (49) with its two solvers, built once; each [`PerchQp::solve`] rewrites `A` and `b`
/// in place and solves. Allocation-free after [`PerchQp::new`] on the active-set path.
pub struct PerchQp {
    params: PerchParams,
    scale: f64,
    solver: DefaultSolver<f64>,
    active_set: DualActiveSet<REDUCED_ROWS>,
    p_colptr: Vec<usize>,
    p_rowval: Vec<usize>,
    p_nzval: Vec<f64>,
    q: Vec<f64>,
    a_colptr: Vec<usize>,
    a_rowval: Vec<usize>,
    a_nzval: Vec<f64>,
    b: Vec<f64>,
    /// `(row, col)` of each entry of `a_nzval`, in CSC order.
    a_entries: Vec<(usize, usize)>,
    dense_a: [[f64; N_VARS]; N_ROWS],
    last_thrust: [f64; N_ROTORS],
    last_thrust_max: [f64; N_ROTORS],
    last_foot_wrench: [f64; 4],
    counters: PerchCounters,
}

/// Which `(row, col)` entries of `A` exist. Fixed for the solver's life, independent of data
/// (a coefficient that is 0 now is still stored, so later updates keep the pattern).
fn a_pattern(row: usize, col: usize) -> bool {
    match row {
        0..=3 => col < N_ROTORS || col == W + row,
        4..=6 => col == FZ,
        7 | 8 => col == FZ || col == MZ,
        9 | 10 => col == FZ || col == MY,
        11 | 12 => col == FZ || col == MX,
        13..=28 => col == (row - ROW_BOUND_LOW) % N_ROTORS,
        _ => false,
    }
}

fn solver_settings(params: &PerchParams) -> Result<DefaultSettings<f64>, ParamError> {
    DefaultSettingsBuilder::default()
        .verbose(false)
        .presolve_enable(false)
        .equilibrate_enable(false)
        .input_sparse_dropzeros(false)
        .max_iter(params.max_iter)
        .tol_gap_abs(params.tolerance)
        .tol_gap_rel(params.tolerance)
        .tol_feas(params.tolerance)
        .direct_solve_method("qdldl".to_string())
        .build()
        .map_err(|_| ParamError {
            field: "tolerance",
            reason: "rejected by Clarabel settings",
        })
}

impl PerchQp {
    /// Build the solver (the only allocations). Fails if `params` does not validate.
    pub fn new(params: PerchParams) -> Result<Self, ParamError> {
        params.validate()?;
        let scale = params.variable_scale();

        // P: upper-triangular CSC, diagonal on the thrust block only.
        let max_weight = params.weight.iter().fold(0.0_f64, |a, b| a.max(*b));
        let mut p_colptr = Vec::with_capacity(N_VARS + 1);
        let mut p_rowval = Vec::with_capacity(N_ROTORS);
        let mut p_nzval = Vec::with_capacity(N_ROTORS);
        p_colptr.push(0);
        for col in 0..N_VARS {
            if col < N_ROTORS {
                p_rowval.push(col);
                p_nzval.push(params.weight[col] / max_weight);
            }
            p_colptr.push(p_rowval.len());
        }

        let mut a_colptr = Vec::with_capacity(N_VARS + 1);
        let mut a_rowval = Vec::new();
        let mut a_entries = Vec::new();
        a_colptr.push(0);
        for col in 0..N_VARS {
            for row in 0..N_ROWS {
                if a_pattern(row, col) {
                    a_rowval.push(row);
                    a_entries.push((row, col));
                }
            }
            a_colptr.push(a_rowval.len());
        }
        // Setup data: pattern entries set to 1 (the values are overwritten every tick).
        let a_nzval = vec![1.0; a_rowval.len()];
        let b = vec![1.0; N_ROWS];
        let q = vec![0.0; N_VARS];

        let p_mat = CscMatrix::new(
            N_VARS,
            N_VARS,
            p_colptr.clone(),
            p_rowval.clone(),
            p_nzval.clone(),
        );
        let a_mat = CscMatrix::new(
            N_ROWS,
            N_VARS,
            a_colptr.clone(),
            a_rowval.clone(),
            a_nzval.clone(),
        );
        let cones: [SupportedConeT<f64>; 2] = [
            ZeroConeT(N_ZERO_ROWS),
            NonnegativeConeT(N_ROWS - N_ZERO_ROWS),
        ];
        let settings = solver_settings(&params)?;
        let solver =
            DefaultSolver::new(&p_mat, &q, &a_mat, &b, &cones, settings).map_err(|_| {
                ParamError {
                    field: "params",
                    reason: "Clarabel refused the setup",
                }
            })?;

        Ok(Self {
            params,
            scale,
            solver,
            active_set: DualActiveSet::new(),
            p_colptr,
            p_rowval,
            p_nzval,
            q,
            a_colptr,
            a_rowval,
            a_nzval,
            b,
            a_entries,
            dense_a: [[0.0; N_VARS]; N_ROWS],
            last_thrust: [0.0; N_ROTORS],
            last_thrust_max: [0.0; N_ROTORS],
            last_foot_wrench: [0.0; 4],
            counters: PerchCounters::default(),
        })
    }

    /// Parameters in use.
    pub fn params(&self) -> &PerchParams {
        &self.params
    }

    /// Ticks per outcome since construction.
    pub fn counters(&self) -> PerchCounters {
        self.counters
    }

    /// Scale `s` dividing every decision variable in the solver's problem.
    pub fn variable_scale(&self) -> f64 {
        self.scale
    }

    /// Solve eq. (49) for `input`. Never panics; a failure returns the safe command.
    pub fn solve(&mut self, input: &PerchInput) -> PerchSolution {
        let solution = self.solve_inner(input);
        self.counters.record(solution.status);
        if solution.fallback {
            self.counters.record_fallback();
        }
        self.last_thrust = solution.thrust;
        self.last_thrust_max = solution.thrust_max;
        self.last_foot_wrench = solution.foot_wrench;
        solution
    }

    fn solve_inner(&mut self, input: &PerchInput) -> PerchSolution {
        if !input_is_finite(input) {
            let previous = if input.previous_thrust.iter().all(|v| v.is_finite()) {
                input.previous_thrust
            } else {
                self.last_thrust
            };
            return self.failure(PerchStatus::NonFiniteInput, &previous, None, input, 0);
        }
        if input.mass <= 0.0 {
            // eq. (47) with m <= 0 would lift the thrust ceiling: no physical robot
            return self.failure(
                PerchStatus::InvalidInput,
                &input.previous_thrust,
                None,
                input,
                0,
            );
        }
        let thrust_max = match self.thrust_max(input) {
            Some(m) => m,
            None => {
                return self.failure(
                    PerchStatus::SingularAllocation,
                    &input.previous_thrust,
                    None,
                    input,
                    0,
                )
            }
        };
        let perch_allocation = self.perch_allocation(&input.foot_allocation);
        if !controlled_rows_independent(&perch_allocation, &self.params.wrench_mask) {
            return self.failure(
                PerchStatus::SingularAllocation,
                &input.previous_thrust,
                Some(thrust_max),
                input,
                0,
            );
        }

        self.fill_rows(input, &perch_allocation, &thrust_max);
        let solution = self.solve_rows(input, &thrust_max);
        if solution.status != PerchStatus::Infeasible || !self.params.relax_rate_limit {
            return solution;
        }
        // Infeasible: is it only the rate limit of eq. (48)? Solve without it and step toward
        // that solution (clip_to_box keeps the step inside δλ_perch).
        self.open_rate_rows(&thrust_max);
        let relaxed = self.solve_rows(input, &thrust_max);
        if !relaxed.status.is_solution() {
            return PerchSolution {
                fallback: solution.fallback || relaxed.fallback,
                ..solution
            };
        }
        // The reported wrench is the one the applied (rate-limited) thrust commands, so the
        // feedback term of eq. (38) refers to what was actually applied.
        let foot_wrench = self.commanded_wrench(&relaxed.thrust, &perch_allocation, input);
        let mut out = self.solution(
            PerchStatus::RateLimited,
            relaxed.thrust,
            foot_wrench,
            thrust_max,
            input,
            solution.iterations.saturating_add(relaxed.iterations),
        );
        out.fallback = solution.fallback || relaxed.fallback;
        out
    }

    /// Solve the rows written by `fill_rows` with the configured solver (active set with
    /// Clarabel as fallback, or Clarabel).
    fn solve_rows(&mut self, input: &PerchInput, thrust_max: &[f64; N_ROTORS]) -> PerchSolution {
        if self.params.solver == PerchSolver::ActiveSet {
            if let Some(solution) = self.solve_active_set(input, thrust_max) {
                return solution;
            }
            let mut solution = self.solve_clarabel(input, *thrust_max);
            solution.fallback = true;
            return solution;
        }
        self.solve_clarabel(input, *thrust_max)
    }

    /// Open the rate rows of eq. (48) so that they never bind inside the bounds of eqs.
    /// (45)-(47): `λ ≤ max(λ_max, 0) + δ` and `−λ ≤ δ` (their coefficients are ±1, so the row
    /// normalisation of `fill_rows` left them unscaled).
    fn open_rate_rows(&mut self, thrust_max: &[f64; N_ROTORS]) {
        let s = self.scale;
        let rates = self.params.thrust_rate_limit;
        for (i, (max, rate)) in thrust_max.iter().zip(rates.iter()).enumerate() {
            self.b[ROW_RATE_HIGH + i] = (max.max(0.0) + rate) / s;
            self.b[ROW_RATE_LOW + i] = rate / s;
        }
    }

    /// `W_foot,t` that `thrust` commands through eq. (38): controlled components
    /// `Q̄_perch,k λ − κ (W_t−1,k − W̃_k)`, the others the measured `W̃_k`.
    fn commanded_wrench(
        &self,
        thrust: &[f64; N_ROTORS],
        perch_allocation: &Matrix4<f64>,
        input: &PerchInput,
    ) -> [f64; 4] {
        let [_, _, fz, mx, my, mz] = input.foot_wrench;
        let measured = [fz, mx, my, mz];
        let mut out = measured;
        for (k, w) in out.iter_mut().enumerate() {
            if self.params.wrench_mask[k] {
                let produced: f64 = (0..N_ROTORS)
                    .map(|i| perch_allocation[(k, i)] * thrust[i])
                    .sum();
                *w = produced
                    - self.params.feedback_gain * (input.previous_foot_wrench[k] - measured[k]);
            }
        }
        out
    }

    /// The default path; `None` hands the tick to Clarabel (iteration cap, unsure).
    fn solve_active_set(
        &mut self,
        input: &PerchInput,
        thrust_max: &[f64; N_ROTORS],
    ) -> Option<PerchSolution> {
        let mut cost = [0.0; N_ROTORS];
        for (c, p) in cost.iter_mut().zip(self.p_nzval.iter()) {
            *c = *p;
        }
        let elimination = reduced::load(&mut self.active_set, &self.dense_a, &self.b, &cost)?;
        let (outcome, iterations) = self.active_set.solve(self.params.active_set_max_iter);
        match outcome {
            ActiveSetOutcome::Optimal => {
                let x = elimination.thrust(&self.active_set.solution());
                let w = elimination.foot_wrench(&x);
                let thrust = x.map(|v| v * self.scale);
                let foot_wrench = w.map(|v| v * self.scale);
                if thrust
                    .iter()
                    .chain(foot_wrench.iter())
                    .any(|v| !v.is_finite())
                {
                    self.active_set.forget_warm_start();
                    return None;
                }
                let thrust = clip_to_box(
                    &thrust,
                    &input.previous_thrust,
                    thrust_max,
                    &self.params.thrust_rate_limit,
                );
                Some(self.solution(
                    PerchStatus::Solved,
                    thrust,
                    foot_wrench,
                    *thrust_max,
                    input,
                    iterations,
                ))
            }
            ActiveSetOutcome::Infeasible => Some(self.failure(
                PerchStatus::Infeasible,
                &input.previous_thrust,
                Some(*thrust_max),
                input,
                iterations,
            )),
            ActiveSetOutcome::IterationLimit | ActiveSetOutcome::Unsure => None,
        }
    }

    /// Clarabel on the full problem (rows already written by `fill_rows`).
    fn solve_clarabel(&mut self, input: &PerchInput, thrust_max: [f64; N_ROTORS]) -> PerchSolution {
        if self.solver.update_A(&self.a_nzval).is_err() || self.solver.update_b(&self.b).is_err() {
            return self.failure(
                PerchStatus::NumericalError,
                &input.previous_thrust,
                Some(thrust_max),
                input,
                0,
            );
        }
        self.solver.solve();
        let iterations = self.solver.solution.iterations;
        let status = match self.solver.solution.status {
            SolverStatus::Solved => PerchStatus::Solved,
            SolverStatus::AlmostSolved => PerchStatus::AlmostSolved,
            SolverStatus::PrimalInfeasible | SolverStatus::AlmostPrimalInfeasible => {
                PerchStatus::Infeasible
            }
            SolverStatus::MaxIterations => PerchStatus::MaxIterations,
            _ => PerchStatus::NumericalError,
        };
        let x = &self.solver.solution.x;
        if !status.is_solution() || x.len() != N_VARS || x.iter().any(|v| !v.is_finite()) {
            let status = if status.is_solution() {
                PerchStatus::NumericalError
            } else {
                status
            };
            return self.failure(
                status,
                &input.previous_thrust,
                Some(thrust_max),
                input,
                iterations,
            );
        }

        let mut thrust = [0.0; N_ROTORS];
        let mut foot_wrench = [0.0; 4];
        for (t, v) in thrust.iter_mut().zip(x.iter()) {
            *t = v * self.scale;
        }
        for (w, v) in foot_wrench.iter_mut().zip(x.iter().skip(N_ROTORS)) {
            *w = v * self.scale;
        }
        // Remove solver-tolerance overshoot so the command is exactly inside eqs. (45), (48).
        let thrust = clip_to_box(
            &thrust,
            &input.previous_thrust,
            &thrust_max,
            &self.params.thrust_rate_limit,
        );
        self.solution(status, thrust, foot_wrench, thrust_max, input, iterations)
    }

    /// `λ_max` of eq. (47) (or the flight-thrust form), `None` if `Q̄` is singular.
    fn thrust_max(&self, input: &PerchInput) -> Option<[f64; N_ROTORS]> {
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

    fn perch_allocation(&self, foot_allocation: &Matrix4<f64>) -> Matrix4<f64> {
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
    fn fill_rows(
        &mut self,
        input: &PerchInput,
        perch_allocation: &Matrix4<f64>,
        thrust_max: &[f64; N_ROTORS],
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
                for i in 0..N_ROTORS {
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
        for i in 0..N_ROTORS {
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

    fn solution(
        &self,
        status: PerchStatus,
        thrust: [f64; N_ROTORS],
        foot_wrench: [f64; 4],
        thrust_max: [f64; N_ROTORS],
        input: &PerchInput,
        iterations: u32,
    ) -> PerchSolution {
        let p = &self.params;
        let [fx, fy, ..] = input.foot_wrench;
        let [fz, mx, my, mz] = foot_wrench;
        let (zmp, zmp_margin) = if fz > 0.0 {
            let px = (fx * p.zmp_z - my) / fz;
            let py = (fy * p.zmp_z + mx) / fz;
            (
                [px, py],
                [p.half_size_x - px.abs(), p.half_size_y - py.abs()],
            )
        } else {
            ([0.0, 0.0], [-p.half_size_x, -p.half_size_y])
        };
        let finite_or_zero = |v: f64| if v.is_finite() { v } else { 0.0 };
        PerchSolution {
            status,
            thrust,
            foot_wrench,
            zmp: zmp.map(finite_or_zero),
            friction_margin: [
                p.mu_x * fz - fx.abs(),
                p.mu_y * fz - fy.abs(),
                p.mu_z * fz - mz.abs(),
            ]
            .map(finite_or_zero),
            zmp_margin: zmp_margin.map(finite_or_zero),
            thrust_min: [0.0; N_ROTORS],
            thrust_max,
            iterations,
            fallback: false,
        }
    }

    /// The safe command for a failed tick (see [`safe_thrust`]); the reported wrench is the
    /// previous tick's so the feedback of eq. (38) keeps its reference.
    fn failure(
        &self,
        status: PerchStatus,
        previous: &[f64; N_ROTORS],
        thrust_max: Option<[f64; N_ROTORS]>,
        input: &PerchInput,
        iterations: u32,
    ) -> PerchSolution {
        let thrust_max = thrust_max.unwrap_or(self.last_thrust_max);
        let thrust = safe_thrust(previous, &thrust_max, &self.params.thrust_rate_limit);
        let foot_wrench = if input.previous_foot_wrench.iter().all(|v| v.is_finite()) {
            input.previous_foot_wrench
        } else {
            self.last_foot_wrench
        };
        let mut input = *input;
        if input.foot_wrench.iter().any(|v| !v.is_finite()) {
            input.foot_wrench = [0.0; 6];
        }
        self.solution(status, thrust, foot_wrench, thrust_max, &input, iterations)
    }

    /// Upper-triangular `P` of the scaled problem as CSC `(colptr, rowval, nzval)`.
    pub fn p_csc(&self) -> (&[usize], &[usize], &[f64]) {
        (&self.p_colptr, &self.p_rowval, &self.p_nzval)
    }

    /// `A` of the scaled problem as CSC `(colptr, rowval, nzval)`, as built for the last
    /// solved tick (the active-set solver reduces exactly these rows; Clarabel gets them).
    /// `A` never changes for the rate relaxation; `b` does (see [`Self::b`]).
    pub fn a_csc(&self) -> (&[usize], &[usize], &[f64]) {
        (&self.a_colptr, &self.a_rowval, &self.a_nzval)
    }

    /// Linear cost `q` (always zero: eq. 37 has no linear term).
    pub fn q(&self) -> &[f64] {
        &self.q
    }

    /// `b` of the scaled problem, as built for the last solved tick (see [`Self::a_csc`]);
    /// after a tick that tried the rate relaxation (status [`PerchStatus::RateLimited`], or
    /// `Infeasible` with `relax_rate_limit` on), with the rate rows of eq. (48) opened.
    pub fn b(&self) -> &[f64] {
        &self.b
    }

    /// Change the weight `N` of eq. (37) in place (`update_P`, same pattern).
    pub fn set_weight(&mut self, weight: [f64; N_ROTORS]) -> Result<(), ParamError> {
        if weight.iter().any(|w| !(w.is_finite() && *w > 0.0)) {
            return Err(ParamError {
                field: "weight",
                reason: "must be finite and > 0",
            });
        }
        let max_weight = weight.iter().fold(0.0_f64, |a, b| a.max(*b));
        for (nz, w) in self.p_nzval.iter_mut().zip(weight.iter()) {
            *nz = w / max_weight;
        }
        self.solver
            .update_P(&self.p_nzval)
            .map_err(|_| ParamError {
                field: "weight",
                reason: "Clarabel refused update_P",
            })?;
        self.params.weight = weight;
        Ok(())
    }
}

fn input_is_finite(input: &PerchInput) -> bool {
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

/// The controlled rows of `Q̄_perch` must be linearly independent for the merged eq. (38) to
/// equal the paper's split form (a zero row would let `W_t` absorb the feedback term).
fn controlled_rows_independent(perch_allocation: &Matrix4<f64>, mask: &[bool; 4]) -> bool {
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
            min_pivot > 1e-9 * largest
        }
        None => false,
    }
}

/// The command of a failed tick: move the previous thrust toward `[λ_min, λ_max]` by at most
/// `δλ_perch` (eq. 48), then clip to `[λ_min, max(λ_min, λ_max)]` (eqs. 45-47). The bounds
/// win over the rate limit, so the result is always inside the thrust limits and finite.
pub fn safe_thrust(
    previous: &[f64; N_ROTORS],
    thrust_max: &[f64; N_ROTORS],
    rate_limit: &[f64; N_ROTORS],
) -> [f64; N_ROTORS] {
    let mut out = [0.0; N_ROTORS];
    for i in 0..N_ROTORS {
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
fn clip_to_box(
    thrust: &[f64; N_ROTORS],
    previous: &[f64; N_ROTORS],
    thrust_max: &[f64; N_ROTORS],
    rate_limit: &[f64; N_ROTORS],
) -> [f64; N_ROTORS] {
    let mut out = [0.0; N_ROTORS];
    for i in 0..N_ROTORS {
        let hi = thrust_max[i].max(0.0);
        let rate_lo = previous[i] - rate_limit[i];
        let rate_hi = previous[i] + rate_limit[i];
        out[i] = thrust[i].max(rate_lo).min(rate_hi).clamp(0.0, hi);
    }
    out
}
