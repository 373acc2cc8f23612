//! The rate relaxation of the perching QP (`PerchParams::relax_rate_limit`): an eq. (49) that
//! is infeasible only through the rate limit of eq. (48) steps toward the solution of the
//! problem without it, instead of holding the previous thrust forever.

// Index loops over parallel per-rotor arrays read clearer than zipped iterators here.
#![allow(clippy::needless_range_loop)]

mod perch_common;

use nalgebra::{Matrix4, Vector3};
use perch_common::{allocation_rows, random_instance};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rdm_core::control::perch::{PerchInput, PerchParams, PerchQp, PerchSolver, PerchStatus};

/// A quadrotor-like layout with the foot 0.4 m behind the CoG, next to rotors 0 and 1.
fn fixed_input() -> PerchInput {
    let positions = [
        Vector3::new(-0.3, -0.2, 0.0),
        Vector3::new(-0.3, 0.2, 0.0),
        Vector3::new(0.3, 0.2, 0.0),
        Vector3::new(0.3, -0.2, 0.0),
    ];
    let normals = [Vector3::z(); 4];
    let foot = Vector3::new(-0.4, 0.0, 0.05);
    PerchInput {
        foot_allocation: allocation_rows(&positions.map(|p| p - foot), &normals),
        allocation: allocation_rows(&positions, &normals),
        mass: 2.5,
        foot_wrench: [0.0; 6],
        previous_thrust: [0.0; 4],
        previous_foot_wrench: [0.0; 4],
        flight_thrust: None,
    }
}

/// Closed loop of `ticks` perching ticks from zero thrust against an ideal contact (the
/// measured normal force is the perch rotors' force, eq. 38's `Q̄_perch λ`, no filter).
/// Returns (status, thrust, measured F_z) per tick.
fn press_from_zero(params: &PerchParams, ticks: usize) -> Vec<(PerchStatus, [f64; 4], f64)> {
    let mut qp = PerchQp::new(params.clone()).unwrap();
    let mut input = fixed_input();
    let perch: Matrix4<f64> = input.foot_allocation;
    let mut out = Vec::new();
    for _ in 0..ticks {
        let sol = qp.solve(&input);
        let fz: f64 = (0..4)
            .filter(|&i| params.perch_rotors[i])
            .map(|i| perch[(0, i)] * sol.thrust[i])
            .sum();
        out.push((sol.status, sol.thrust, fz));
        input.previous_thrust = sol.thrust;
        if sol.status.is_solution() {
            input.previous_foot_wrench = sol.foot_wrench;
        }
        input.foot_wrench[2] = fz;
    }
    out
}

fn high_press(solver: PerchSolver, relax: bool) -> PerchParams {
    PerchParams {
        epsilon_z: 12.0, // beyond one 5 N step on each of the two perch rotors
        solver,
        relax_rate_limit: relax,
        ..PerchParams::default()
    }
}

#[test]
fn without_the_relaxation_a_large_epsilon_z_latches_at_zero_thrust() {
    for solver in [PerchSolver::ActiveSet, PerchSolver::Clarabel] {
        let run = press_from_zero(&high_press(solver, false), 40);
        for (status, thrust, _) in &run {
            assert_eq!(*status, PerchStatus::Infeasible, "{solver:?}");
            assert_eq!(
                *thrust, [0.0; 4],
                "{solver:?}: the safe command holds zero thrust"
            );
        }
    }
}

#[test]
fn with_the_relaxation_the_thrust_ramps_by_the_rate_limit_and_then_solves() {
    let mut runs = Vec::new();
    for solver in [PerchSolver::ActiveSet, PerchSolver::Clarabel] {
        let params = high_press(solver, true);
        let run = press_from_zero(&params, 40);
        let mut previous = [0.0; 4];
        for (status, thrust, _) in &run {
            for i in 0..4 {
                let step = (thrust[i] - previous[i]).abs();
                assert!(
                    step <= params.thrust_rate_limit[i] + 1e-9,
                    "{solver:?} step {step}"
                );
                assert!(thrust[i] >= 0.0);
                // Clarabel (interior point) stays ~1e-3 N inside the lambda >= 0 bound
                let tol = if solver == PerchSolver::Clarabel {
                    5e-3
                } else {
                    1e-9
                };
                if !params.perch_rotors[i] {
                    assert!(thrust[i].abs() < tol, "{solver:?}: rotor {i}: {thrust:?}");
                }
            }
            assert!(
                matches!(status, PerchStatus::RateLimited | PerchStatus::Solved),
                "{solver:?}: {status:?}"
            );
            previous = *thrust;
        }
        // the first tick is the full rate step on both perch rotors (the relaxed optimum is
        // beyond it), and the loop ends solved, pressing at least epsilon_z
        assert_eq!(run[0].0, PerchStatus::RateLimited);
        assert!((run[0].1[0] - 5.0).abs() < 1e-6 && (run[0].1[1] - 5.0).abs() < 1e-6);
        let (status, _, fz) = run[run.len() - 1];
        assert_eq!(status, PerchStatus::Solved, "{solver:?}");
        assert!(fz >= params.epsilon_z - 1e-6, "{solver:?}: F_z {fz}");
        runs.push(run);
    }
    // both solvers take the same path (Clarabel to its tolerance)
    for (a, c) in runs[0].iter().zip(runs[1].iter()) {
        assert_eq!(a.0, c.0);
        for i in 0..4 {
            assert!((a.1[i] - c.1[i]).abs() < 5e-3, "{:?} vs {:?}", a.1, c.1);
        }
    }
}

/// Independent of `open_rate_rows`: the same instance with a rate limit too large to bind
/// and no relaxation, then the rate box applied by hand.
fn relaxed_by_hand(params: &PerchParams, input: &PerchInput) -> Option<[f64; 4]> {
    let wide = PerchParams {
        thrust_rate_limit: [1.0e3; 4],
        relax_rate_limit: false,
        solver: PerchSolver::Clarabel,
        ..params.clone()
    };
    let sol = PerchQp::new(wide).unwrap().solve(input);
    if sol.status != PerchStatus::Solved {
        return None;
    }
    let mut out = [0.0; 4];
    for i in 0..4 {
        let lo = input.previous_thrust[i] - params.thrust_rate_limit[i];
        let hi = input.previous_thrust[i] + params.thrust_rate_limit[i];
        out[i] = sol.thrust[i]
            .clamp(lo, hi)
            .clamp(0.0, sol.thrust_max[i].max(0.0));
    }
    Some(out)
}

#[test]
fn rate_limited_ticks_step_toward_the_problem_without_eq_48() {
    let mut rng = ChaCha8Rng::seed_from_u64(0x5EED_0048);
    let (mut relaxed, mut still_infeasible) = (0usize, 0usize);
    for k in 0..6000 {
        let params = PerchParams {
            thrust_rate_limit: [[0.5, 1.0, 2.0, 5.0][k % 4]; 4],
            ..PerchParams::default()
        };
        let input = random_instance(&mut rng, &params);
        for solver in [PerchSolver::ActiveSet, PerchSolver::Clarabel] {
            let sol = PerchQp::new(PerchParams {
                solver,
                ..params.clone()
            })
            .unwrap()
            .solve(&input);
            let reference = relaxed_by_hand(&params, &input);
            match sol.status {
                PerchStatus::RateLimited => {
                    let by_hand = reference.expect("rate limited, but infeasible without eq. 48");
                    for i in 0..4 {
                        let d = (sol.thrust[i] - by_hand[i]).abs();
                        assert!(d < 2e-3, "{solver:?} rotor {i}: {d} N on {input:?}");
                    }
                    relaxed += 1;
                }
                PerchStatus::Infeasible => {
                    // then the problem is infeasible without eq. (48) too (boundary cases of
                    // the reference's tolerance aside)
                    if let Some(t) = reference {
                        let strict = PerchQp::new(PerchParams {
                            relax_rate_limit: false,
                            ..params.clone()
                        })
                        .unwrap()
                        .solve(&input);
                        assert_eq!(strict.status, PerchStatus::Infeasible, "{t:?}");
                    }
                    assert_eq!(sol.thrust, safe_hold(&input, &sol.thrust_max));
                    still_infeasible += 1;
                }
                _ => {}
            }
        }
    }
    assert!(
        relaxed > 500,
        "only {relaxed} rate-limited ticks: the test lost its teeth"
    );
    assert!(
        still_infeasible > 100,
        "only {still_infeasible} infeasible ticks"
    );
}

/// The safe command of an infeasible tick: the previous thrust, clipped to the bounds.
fn safe_hold(input: &PerchInput, thrust_max: &[f64; 4]) -> [f64; 4] {
    let mut out = [0.0; 4];
    for i in 0..4 {
        out[i] = input.previous_thrust[i].clamp(0.0, thrust_max[i].max(0.0));
    }
    out
}
