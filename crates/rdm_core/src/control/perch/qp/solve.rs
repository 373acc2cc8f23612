//! Solving the assembled rows: the dense active-set path on the reduced problem, Clarabel
//! as the alternative and the fallback, and the status and reported values of a tick
//! (solved, or the safe command of a failure).

use clarabel::solver::{DefaultSettings, DefaultSettingsBuilder, IPSolver, SolverStatus};

use super::safe::{clip_to_box, safe_thrust};
use super::{PerchInput, PerchQp, PerchSolution};
use crate::control::perch::active_set::ActiveSetOutcome;
use crate::control::perch::dims::N_VARS;
use crate::control::perch::error::ParamError;
use crate::control::perch::params::{PerchParams, PerchSolver};
use crate::control::perch::reduced;
use crate::control::perch::status::PerchStatus;
use crate::PERCH_ROTORS;

pub(super) fn solver_settings(params: &PerchParams) -> Result<DefaultSettings<f64>, ParamError> {
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
    /// Solve the rows written by `fill_rows` with the configured solver (active set with
    /// Clarabel as fallback, or Clarabel).
    pub(super) fn solve_rows(
        &mut self,
        input: &PerchInput,
        thrust_max: &[f64; PERCH_ROTORS],
    ) -> PerchSolution {
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

    /// The default path; `None` hands the tick to Clarabel (iteration cap, unsure).
    fn solve_active_set(
        &mut self,
        input: &PerchInput,
        thrust_max: &[f64; PERCH_ROTORS],
    ) -> Option<PerchSolution> {
        let mut cost = [0.0; PERCH_ROTORS];
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
    fn solve_clarabel(
        &mut self,
        input: &PerchInput,
        thrust_max: [f64; PERCH_ROTORS],
    ) -> PerchSolution {
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

        let mut thrust = [0.0; PERCH_ROTORS];
        let mut foot_wrench = [0.0; 4];
        for (t, v) in thrust.iter_mut().zip(x.iter()) {
            *t = v * self.scale;
        }
        for (w, v) in foot_wrench.iter_mut().zip(x.iter().skip(PERCH_ROTORS)) {
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

    pub(super) fn solution(
        &self,
        status: PerchStatus,
        thrust: [f64; PERCH_ROTORS],
        foot_wrench: [f64; 4],
        thrust_max: [f64; PERCH_ROTORS],
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
            thrust_min: [0.0; PERCH_ROTORS],
            thrust_max,
            iterations,
            fallback: false,
        }
    }

    /// The safe command for a failed tick (see [`safe_thrust`]); the reported wrench is the
    /// previous tick's so the feedback of eq. (38) keeps its reference.
    pub(super) fn failure(
        &self,
        status: PerchStatus,
        previous: &[f64; PERCH_ROTORS],
        thrust_max: Option<[f64; PERCH_ROTORS]>,
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
}
