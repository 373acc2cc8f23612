//! Continuous algebraic Riccati equation (CARE) solver for the LQI synthesis (eq. 27).
//!
//! Solves `AᵀP + PA − PBR⁻¹BᵀP + Q = 0` for the stabilising P and returns the gain
//! `K = −R⁻¹BᵀP` (so that `u = K x`, the sign convention of eq. (28)).
//!
//! Fixed size: [`N_STATE`] = 12 states, [`N_INPUT`] = [`MAX_ROTORS`] inputs; a robot with
//! fewer rotors leaves the extra columns of B zero (their rows of K come out zero and P is
//! the P of the smaller problem: `B R⁻¹ Bᵀ` does not see them). Two methods:
//! - cold: Newton iteration for the matrix sign function of the 24x24 Hamiltonian with
//!   determinant scaling ([`sign`]);
//! - warm: Kleinman (Newton-Lyapunov) iteration started from the previous gain, each
//!   Lyapunov equation solved by the sign-function (Roberts) iteration ([`kleinman`]).
//!   As in the JSK flight code, a warm start that does not converge within its bound falls
//!   back to the cold method.
//!
//! Every solution is accepted only if its relative ARE residual is below
//! [`CareConfig::residual_tolerance`]. All matrices live on the stack: nothing allocates.

mod dense;
mod kleinman;
mod sign;

use nalgebra::{Cholesky, SMatrix};

use crate::MAX_ROTORS;

/// Number of LQI states (`x = [z, ż, φ, φ̇, θ, θ̇, ψ, ψ̇, ∫z, ∫φ, ∫θ, ∫ψ]`).
pub const N_STATE: usize = 12;
/// Number of inputs (one thrust per rotor).
pub const N_INPUT: usize = MAX_ROTORS;

/// n x n state matrix (A, Q, P).
pub type StateMatrix = SMatrix<f64, N_STATE, N_STATE>;
/// n x m input matrix B.
pub type InputMatrix = SMatrix<f64, N_STATE, N_INPUT>;
/// m x m input weight R.
pub type InputWeight = SMatrix<f64, N_INPUT, N_INPUT>;
/// m x n feedback gain K (`u = K x`).
pub type GainMatrix = SMatrix<f64, N_INPUT, N_STATE>;

/// Iteration bounds and tolerances of the solver.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CareConfig {
    /// Bound on the Newton sign-function iterations of the cold method.
    pub max_sign_iterations: usize,
    /// Bound on the Kleinman iterations of the warm method (JSK: 10).
    pub max_kleinman_iterations: usize,
    /// Kleinman stops when `max|ΔK| <= kleinman_tolerance * max(1, max|K|)`.
    /// JSK uses an absolute 0.01; the default (1e-9) is tighter so warm and cold agree to
    /// 1e-8 (Newton converges quadratically, so this costs about one extra iteration).
    pub kleinman_tolerance: f64,
    /// Bound on the Roberts iterations of one Lyapunov solve inside Kleinman.
    pub max_lyapunov_iterations: usize,
    /// A solution is rejected if `|res|_F / (|Q|_F + 2|AᵀP|_F + |PGP|_F)` exceeds this.
    /// A sanity bound, not the accuracy: on ill-conditioned LQI problems (cond P ~ 1e7)
    /// even scipy's solution has a relative residual near 1e-7 by this measure.
    pub residual_tolerance: f64,
    /// Newton (Kleinman) refinement steps after the cold sign-function solve (0: none).
    pub polish_steps: usize,
}

impl Default for CareConfig {
    fn default() -> Self {
        Self {
            max_sign_iterations: 60,
            max_kleinman_iterations: 10,
            kleinman_tolerance: 1e-9,
            max_lyapunov_iterations: 60,
            residual_tolerance: 1e-6,
            polish_steps: 1,
        }
    }
}

/// Which method produced a solution.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CareMethod {
    /// Matrix-sign function of the Hamiltonian (cold start).
    SignFunction,
    /// Kleinman iteration warm-started from the previous gain.
    Kleinman,
}

/// Report of a successful solve (the "Converged" status).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CareReport {
    /// Method that produced the returned solution.
    pub method: CareMethod,
    /// Iterations of that method (sign or Kleinman iterations).
    pub iterations: usize,
    /// True when a warm start was tried, failed and the cold method took over.
    pub fell_back: bool,
    /// Relative ARE residual of the returned P.
    pub relative_residual: f64,
}

/// Why no solution was returned. The solver never panics.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CareError {
    /// An argument holds NaN/inf, is not symmetric, or R is not positive definite.
    InvalidInput {
        /// Name of the offending argument (`"a"`, `"b"`, `"q"`, `"r"`, `"k0"`).
        argument: &'static str,
    },
    /// The Hamiltonian has eigenvalues on (or numerically at) the imaginary axis: (A, B)
    /// is not stabilisable or (A, Q) not detectable.
    NotStabilizable,
    /// The iteration bound was hit, or the result failed the residual check.
    NotConverged {
        /// Iterations spent by the last method tried.
        iterations: usize,
    },
}

impl core::fmt::Display for CareError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::InvalidInput { argument } => write!(f, "invalid CARE input `{argument}`"),
            Self::NotStabilizable => {
                write!(f, "CARE has no stabilising solution (Hamiltonian eigenvalue on the imaginary axis)")
            }
            Self::NotConverged { iterations } => {
                write!(f, "CARE solver did not converge ({iterations} iterations)")
            }
        }
    }
}

impl std::error::Error for CareError {}

/// The validated problem data shared by both methods.
#[derive(Clone, Copy, Debug)]
pub(crate) struct CareProblem {
    pub a: StateMatrix,
    pub b: InputMatrix,
    pub q: StateMatrix,
    pub r_inv: InputWeight,
    /// `G = B R⁻¹ Bᵀ`.
    pub g: StateMatrix,
}

impl CareProblem {
    pub(crate) fn new(
        a: &StateMatrix,
        b: &InputMatrix,
        q: &StateMatrix,
        r: &InputWeight,
    ) -> Result<Self, CareError> {
        check_finite(a.as_slice(), "a")?;
        check_finite(b.as_slice(), "b")?;
        check_finite(q.as_slice(), "q")?;
        check_finite(r.as_slice(), "r")?;
        check_symmetric(q, "q")?;
        check_symmetric(r, "r")?;
        let cholesky = Cholesky::new(*r).ok_or(CareError::InvalidInput { argument: "r" })?;
        let r_inv = cholesky.inverse();
        let g = b * r_inv * b.transpose();
        let g = (g + g.transpose()) * 0.5;
        Ok(Self {
            a: *a,
            b: *b,
            q: *q,
            r_inv,
            g,
        })
    }

    /// `K = −R⁻¹BᵀP`.
    pub(crate) fn gain(&self, p: &StateMatrix) -> GainMatrix {
        -(self.r_inv * self.b.transpose() * p)
    }

    /// Relative Frobenius residual of the ARE at `p`.
    pub(crate) fn relative_residual(&self, p: &StateMatrix) -> f64 {
        let atp = self.a.transpose() * p;
        let pgp = p * self.g * p;
        let residual = atp + atp.transpose() - pgp + self.q;
        let scale = self.q.norm() + 2.0 * atp.norm() + pgp.norm();
        if scale == 0.0 {
            residual.norm()
        } else {
            residual.norm() / scale
        }
    }
}

fn check_finite(values: &[f64], argument: &'static str) -> Result<(), CareError> {
    if values.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(CareError::InvalidInput { argument })
    }
}

fn check_symmetric<const N: usize>(
    m: &SMatrix<f64, N, N>,
    argument: &'static str,
) -> Result<(), CareError> {
    let tolerance = 1e-10 * m.amax().max(f64::MIN_POSITIVE);
    if (m - m.transpose()).amax() <= tolerance {
        Ok(())
    } else {
        Err(CareError::InvalidInput { argument })
    }
}

/// Stateful CARE solver: keeps the last solution for the warm start.
#[derive(Clone, Debug)]
pub struct CareSolver {
    config: CareConfig,
    p: StateMatrix,
    k: GainMatrix,
    has_solution: bool,
}

impl Default for CareSolver {
    fn default() -> Self {
        Self::new(CareConfig::default())
    }
}

impl CareSolver {
    /// A solver with no previous solution (the first solve is cold).
    pub fn new(config: CareConfig) -> Self {
        Self {
            config,
            p: StateMatrix::zeros(),
            k: GainMatrix::zeros(),
            has_solution: false,
        }
    }

    /// The configuration in use.
    pub fn config(&self) -> &CareConfig {
        &self.config
    }

    /// Stabilising solution P of the last successful solve (zeros before the first).
    pub fn p(&self) -> &StateMatrix {
        &self.p
    }

    /// Gain `K = −R⁻¹BᵀP` of the last successful solve.
    pub fn k(&self) -> &GainMatrix {
        &self.k
    }

    /// True once a solve has succeeded (the next [`Self::solve`] is warm).
    pub fn has_solution(&self) -> bool {
        self.has_solution
    }

    /// Forgets the previous solution so the next solve is cold.
    pub fn reset(&mut self) {
        self.has_solution = false;
    }

    /// Solves the CARE: Kleinman from the previous gain if there is one, with the cold
    /// sign-function method as the fallback; cold otherwise.
    pub fn solve(
        &mut self,
        a: &StateMatrix,
        b: &InputMatrix,
        q: &StateMatrix,
        r: &InputWeight,
    ) -> Result<CareReport, CareError> {
        let problem = CareProblem::new(a, b, q, r)?;
        if self.has_solution {
            let k0 = self.k;
            self.solve_from(&problem, &k0)
        } else {
            self.solve_cold_problem(&problem, false)
        }
    }

    /// Solves with the cold sign-function method, ignoring any previous solution.
    pub fn solve_cold(
        &mut self,
        a: &StateMatrix,
        b: &InputMatrix,
        q: &StateMatrix,
        r: &InputWeight,
    ) -> Result<CareReport, CareError> {
        let problem = CareProblem::new(a, b, q, r)?;
        self.solve_cold_problem(&problem, false)
    }

    /// Kleinman warm start from the given gain `k0` (`u = k0 x`), falling back to the
    /// cold method if it fails. Exposed so the fallback path can be exercised.
    pub fn solve_warm_from(
        &mut self,
        a: &StateMatrix,
        b: &InputMatrix,
        q: &StateMatrix,
        r: &InputWeight,
        k0: &GainMatrix,
    ) -> Result<CareReport, CareError> {
        let problem = CareProblem::new(a, b, q, r)?;
        check_finite(k0.as_slice(), "k0")?;
        self.solve_from(&problem, k0)
    }

    fn solve_from(
        &mut self,
        problem: &CareProblem,
        k0: &GainMatrix,
    ) -> Result<CareReport, CareError> {
        if let Ok(outcome) = kleinman::solve(problem, k0, &self.config) {
            let relative_residual = problem.relative_residual(&outcome.p);
            if outcome.converged && relative_residual <= self.config.residual_tolerance {
                self.accept(problem, outcome.p);
                return Ok(CareReport {
                    method: CareMethod::Kleinman,
                    iterations: outcome.iterations,
                    fell_back: false,
                    relative_residual,
                });
            }
        }
        self.solve_cold_problem(problem, true)
    }

    fn solve_cold_problem(
        &mut self,
        problem: &CareProblem,
        fell_back: bool,
    ) -> Result<CareReport, CareError> {
        let (mut p, iterations) = sign::solve(problem, &self.config)?;
        let mut relative_residual = problem.relative_residual(&p);
        if self.config.polish_steps > 0 {
            // Newton (Kleinman) steps from the sign-function solution: on ill-conditioned
            // problems the sign function alone is accurate to ~1e-7, one step to ~1e-9.
            let k = problem.gain(&p);
            let polish = CareConfig {
                max_kleinman_iterations: self.config.polish_steps,
                ..self.config
            };
            if let Ok(polished) = kleinman::solve(problem, &k, &polish) {
                let polished_residual = problem.relative_residual(&polished.p);
                // Guard against a diverging step; residuals at rounding level are noisy.
                if polished_residual <= (10.0 * relative_residual).max(1e-13) {
                    p = polished.p;
                    relative_residual = polished_residual;
                }
            }
        }
        if relative_residual > self.config.residual_tolerance {
            return Err(CareError::NotConverged { iterations });
        }
        self.accept(problem, p);
        Ok(CareReport {
            method: CareMethod::SignFunction,
            iterations,
            fell_back,
            relative_residual,
        })
    }

    fn accept(&mut self, problem: &CareProblem, p: StateMatrix) {
        self.p = p;
        self.k = problem.gain(&p);
        self.has_solution = true;
    }
}
