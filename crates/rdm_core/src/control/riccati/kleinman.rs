//! Warm CARE method: Kleinman's Newton iteration on the gain.
//!
//! From a stabilising `K_0` (`u = K x`): solve the Lyapunov equation
//! `(A + BK_j)ᵀP_j + P_j(A + BK_j) + Q + K_jᵀRK_j = 0`, set `K_{j+1} = −R⁻¹BᵀP_j`, until
//! `max|ΔK|` is below the tolerance. Each Lyapunov equation is solved by the Roberts
//! sign-function iteration, which also detects a non-stabilising `K_j` (the closed loop
//! sign is then not −I) so the caller can fall back to the cold method.

use super::dense::{invert_in_place, norm1};
use super::{CareConfig, CareError, CareProblem, GainMatrix, InputWeight, StateMatrix, N_STATE};

/// Step below which the Roberts iteration has converged.
const LYAPUNOV_STEP_TOLERANCE: f64 = 1e-7;
/// Relative step below which determinant scaling is switched off.
const SCALING_OFF: f64 = 1e-2;

/// Outcome of a bounded Kleinman run.
pub(super) struct KleinmanOutcome {
    /// Last P computed (from a stabilising gain).
    pub p: StateMatrix,
    /// Iterations performed.
    pub iterations: usize,
    /// Whether `max|ΔK|` fell below the tolerance.
    pub converged: bool,
}

/// Runs at most `max_kleinman_iterations` Newton steps from `k0`. Errors if `k0` (or an
/// iterate) is not stabilising, so no P is available.
pub(super) fn solve(
    problem: &CareProblem,
    k0: &GainMatrix,
    config: &CareConfig,
) -> Result<KleinmanOutcome, CareError> {
    // R is recovered from R⁻¹ once (4x4); the gain update only needs R⁻¹.
    let mut r = problem.r_inv;
    if invert_in_place::<4>(&mut r).is_err() {
        return Err(CareError::InvalidInput { argument: "r" });
    }
    let r: InputWeight = (r + r.transpose()) * 0.5;
    let mut k = *k0;
    let mut last_p = None;
    for iteration in 1..=config.max_kleinman_iterations {
        let closed_loop = problem.a + problem.b * k;
        let constant = problem.q + k.transpose() * r * k;
        let p = lyapunov(&closed_loop, &constant, config.max_lyapunov_iterations).ok_or(
            CareError::NotConverged {
                iterations: iteration,
            },
        )?;
        last_p = Some(p);
        let next = problem.gain(&p);
        let change = (next - k).amax();
        k = next;
        if !change.is_finite() {
            return Err(CareError::NotConverged {
                iterations: iteration,
            });
        }
        if change <= config.kleinman_tolerance * k.amax().max(1.0) {
            return Ok(KleinmanOutcome {
                p,
                iterations: iteration,
                converged: true,
            });
        }
    }
    last_p
        .map(|p| KleinmanOutcome {
            p,
            iterations: config.max_kleinman_iterations,
            converged: false,
        })
        .ok_or(CareError::NotConverged {
            iterations: config.max_kleinman_iterations,
        })
}

/// Solves `AᵀX + XA + C = 0` for a Hurwitz A (Roberts' sign iteration with determinant
/// scaling). Returns `None` if A is singular, not Hurwitz, or the bound is hit.
fn lyapunov(a: &StateMatrix, c: &StateMatrix, max_iterations: usize) -> Option<StateMatrix> {
    // Invariant: A_kᵀX + XA_k + C_k = 0 for the same X; A_k → sign(A) = −I, C_k → 2X.
    let mut a_k = *a;
    let mut c_k = *c;
    let mut scaling = true;
    let mut converged = false;
    for _ in 0..max_iterations {
        let mut a_inv = a_k;
        let log_det = invert_in_place(&mut a_inv).ok()?;
        let scale = if scaling {
            (-log_det / N_STATE as f64).exp()
        } else {
            1.0
        };
        if !scale.is_finite() || scale <= 0.0 {
            return None;
        }
        let next_a = (a_k * scale + a_inv * (1.0 / scale)) * 0.5;
        let next_c = (c_k * scale + a_inv.transpose() * c_k * a_inv * (1.0 / scale)) * 0.5;
        let step = norm1(&(next_a - a_k));
        let size = norm1(&next_a);
        a_k = next_a;
        c_k = next_c;
        if !size.is_finite() {
            return None;
        }
        if step <= SCALING_OFF * size {
            scaling = false;
        }
        if converged {
            break;
        }
        if step <= LYAPUNOV_STEP_TOLERANCE * size {
            converged = true;
        }
    }
    if !converged {
        return None;
    }
    // A non-Hurwitz A converges to a sign matrix other than −I.
    let mut distance = a_k;
    for i in 0..N_STATE {
        distance[(i, i)] += 1.0;
    }
    if norm1(&distance) > 1e-6 {
        return None;
    }
    let x = c_k * 0.5;
    let x = (x + x.transpose()) * 0.5;
    if x.iter().any(|v| !v.is_finite()) {
        return None;
    }
    Some(x)
}
