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
//!
//! Files: `rows` (the problem assembly: the sparsity pattern, the rows of the table above,
//! `λ_max` of eq. 47, the input checks), `solve` (the solvers and the status of a tick),
//! `safe` (the safe command of a failed tick and the clip of a solved one).

mod rows;
mod safe;
mod solve;

pub use safe::safe_thrust;

use clarabel::algebra::CscMatrix;
use clarabel::solver::{DefaultSolver, NonnegativeConeT, SupportedConeT, ZeroConeT};
use nalgebra::{Matrix4, Matrix6x4};

use super::active_set::DualActiveSet;
use super::dims::{N_ROWS, N_VARS, N_ZERO_ROWS};
use super::error::ParamError;
use super::params::PerchParams;
use super::plane::ContactPlane;
use super::reduced::REDUCED_ROWS;
use super::status::{PerchCounters, PerchStatus};
use crate::PERCH_ROTORS;
use rows::{a_pattern, controlled_rows_independent, input_is_finite};
use solve::solver_settings;

/// Inputs of one perching QP. All wrenches are in the contact plane's coordinates
/// ([`ContactPlane`]: axes `t₁, t₂, d`, moments about the face centre; for the paper's ceiling
/// the foot frame at its origin), with the sign of the wrench the foot applies to the surface
/// (`F_z > 0` presses, eq. 39). [`PerchQp::solve_foot`] takes foot-axes quantities instead.
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
    pub previous_thrust: [f64; PERCH_ROTORS],
    /// `W_foot,t−1 = [F_z, M_x, M_y, M_z]` decided at the previous tick, for eq. (38).
    pub previous_foot_wrench: [f64; 4],
    /// `None`: eq. (47). `Some(λ_flight)`: bound the total thrust instead,
    /// `λ_max = λ_rotor_max − λ_flight` (eq. 20 with the flight thrust actually commanded).
    pub flight_thrust: Option<[f64; PERCH_ROTORS]>,
}

/// Result of one perching QP. Every field is finite whatever the input.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PerchSolution {
    /// Outcome; anything but solved/almost solved/rate limited means `thrust` is the safe
    /// command.
    pub status: PerchStatus,
    /// `λ_perch,t` [N], inside `[thrust_min, thrust_max]`.
    pub thrust: [f64; PERCH_ROTORS],
    /// `W_foot,t = [F_z, M_x, M_y, M_z]` of the solution (previous one on failure).
    pub foot_wrench: [f64; 4],
    /// ZMP `[p_x, p_y]` of eqs. (43)-(44) with `foot_wrench`'s `F_z` [m].
    pub zmp: [f64; 2],
    /// `[μ_x F_z − |F̃_x|, μ_y F_z − |F̃_y|, μ_z F_z − |M_z|]` (≥ 0 when eqs. 40-41 hold).
    pub friction_margin: [f64; 3],
    /// `[H_x − |p_x|, H_y − |p_y|]` (≥ 0 when eq. 42 holds).
    pub zmp_margin: [f64; 2],
    /// `λ_min` of eq. (46).
    pub thrust_min: [f64; PERCH_ROTORS],
    /// `λ_max` used this tick (eq. 47 or the flight-thrust form; last valid one on failure).
    pub thrust_max: [f64; PERCH_ROTORS],
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
    plane: ContactPlane,
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
    last_thrust: [f64; PERCH_ROTORS],
    last_thrust_max: [f64; PERCH_ROTORS],
    last_foot_wrench: [f64; 4],
    counters: PerchCounters,
}

impl PerchQp {
    /// Build the solver (the only allocations). Fails if `params` does not validate.
    pub fn new(params: PerchParams) -> Result<Self, ParamError> {
        params.validate()?;
        let plane = ContactPlane::new(params.contact_normal, params.contact_center)?;
        let scale = params.variable_scale();

        // P: upper-triangular CSC, diagonal on the thrust block only.
        let max_weight = params.weight.iter().fold(0.0_f64, |a, b| a.max(*b));
        let mut p_colptr = Vec::with_capacity(N_VARS + 1);
        let mut p_rowval = Vec::with_capacity(PERCH_ROTORS);
        let mut p_nzval = Vec::with_capacity(PERCH_ROTORS);
        p_colptr.push(0);
        for col in 0..N_VARS {
            if col < PERCH_ROTORS {
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
            plane,
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
            last_thrust: [0.0; PERCH_ROTORS],
            last_thrust_max: [0.0; PERCH_ROTORS],
            last_foot_wrench: [0.0; 4],
            counters: PerchCounters::default(),
        })
    }

    /// Parameters in use.
    pub fn params(&self) -> &PerchParams {
        &self.params
    }

    /// The contact plane of `params.contact_normal` and `params.contact_center`.
    pub fn plane(&self) -> &ContactPlane {
        &self.plane
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

    /// Solve eq. (49) from foot-axes quantities: `input.foot_wrench` in foot axes about the
    /// foot origin, `foot_allocation` the six rows `[F_x, F_y, F_z, M_x, M_y, M_z]` unit thrusts
    /// produce there (`input.foot_allocation` is replaced by the plane's rows of it;
    /// `previous_foot_wrench` stays in plane coordinates, as the solutions report it).
    pub fn solve_foot(
        &mut self,
        foot_allocation: &Matrix6x4<f64>,
        input: &PerchInput,
    ) -> PerchSolution {
        let on_plane = PerchInput {
            foot_allocation: self.plane.allocation(foot_allocation),
            foot_wrench: self.plane.wrench(&input.foot_wrench),
            ..*input
        };
        self.solve(&on_plane)
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
}
