//! 100,000 seeded random perching QPs (count via `RDM_PERCH_INSTANCES`): every instance the
//! analytic check calls feasible is solved, satisfies eqs. (38)-(48), and every instance it
//! calls infeasible is reported infeasible with an in-bounds safe command. Both solvers run
//! on every instance and the default active-set answer must agree with Clarabel's.
//!
//! Agreement tolerance: the scaled cost `f(x) = ½ xᵀPx` is strongly convex in the thrusts
//! with modulus `min P_ii` (= 1 for Table VII's N), and the active-set answer is optimal to
//! ~1e-10. For Clarabel's point, optimality `∇f(x*)ᵀ(x − x*) ≥ 0` gives
//! `f(x) − f(x*) ≥ ½ min P_ii ‖x − x*‖²`, and its duality gap is ≤ 1e-8 (`tol_gap_abs`), so
//! `‖x − x*‖ ≤ √(2e-8) ≈ 1.4e-4` scaled, i.e. 4.2e-3 N at `s = 30 N`: the thrusts must agree
//! to 5e-3 N. The optimal costs must agree to Clarabel's own gap criterion (1e-8 + 1e-7 rel).

mod perch_common;

use perch_common::{feasibility_margin, random_instance, thrust_max};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rdm_core::control::perch::{PerchParams, PerchQp, PerchSolution, PerchSolver, PerchStatus};

const TOL: f64 = 1e-6;
/// Thrust agreement active set vs Clarabel [N] (module doc).
const THRUST_AGREEMENT: f64 = 5e-3;

/// Scaled cost `½ xᵀPx` of eq. (37) for a solution, as both solvers see it.
fn scaled_cost(sol: &PerchSolution, params: &PerchParams) -> f64 {
    let s = params.variable_scale();
    let max_w = params.weight.iter().fold(0.0_f64, |a, b| a.max(*b));
    0.5 * sol
        .thrust
        .iter()
        .zip(params.weight.iter())
        .map(|(l, w)| w / max_w * (l / s) * (l / s))
        .sum::<f64>()
}

fn instance_count() -> usize {
    std::env::var("RDM_PERCH_INSTANCES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(100_000)
}

#[test]
fn random_feasible_instances_all_solve_and_satisfy_constraints() {
    // eq. (49) itself: no rate relaxation (tests/perch_rate_relax.rs covers that)
    let params = PerchParams {
        relax_rate_limit: false,
        ..PerchParams::default()
    };
    assert_eq!(params.solver, PerchSolver::ActiveSet);
    let mut qp = PerchQp::new(params.clone()).unwrap();
    let mut clarabel = PerchQp::new(PerchParams {
        solver: PerchSolver::Clarabel,
        ..params.clone()
    })
    .unwrap();
    let (mut worst_thrust, mut worst_cost, mut max_passes) = (0.0_f64, f64::NEG_INFINITY, 0u32);
    let mut rng = ChaCha8Rng::seed_from_u64(0x5EED_0001);
    let wanted = instance_count();
    let (mut feasible, mut infeasible, mut max_iter) = (0usize, 0usize, 0u32);
    // Instances within 1e-3 N of the feasibility boundary may go either way; their failures
    // are still counted by the controller, so track them to reconcile the counters.
    let mut boundary_failures = 0usize;
    let mut wrong_infeasible = Vec::new();
    let started = std::time::Instant::now();
    while feasible < wanted {
        let input = random_instance(&mut rng, &params);
        let Some(margin) = feasibility_margin(&input, &params) else {
            continue;
        };
        let sol = qp.solve(&input);
        let reference = clarabel.solve(&input);
        let lmax = thrust_max(&input, &params).unwrap();
        for (thrust, bound) in sol.thrust.iter().zip(lmax) {
            assert!(thrust.is_finite());
            assert!(*thrust >= 0.0 && *thrust <= bound.max(0.0) + 1e-9);
        }
        if margin > 1e-3 {
            feasible += 1;
            assert_eq!(
                sol.status,
                PerchStatus::Solved,
                "margin {margin}, input {input:?}"
            );
            assert!(!sol.fallback, "fallback on a feasible instance: {input:?}");
            assert_eq!(reference.status, PerchStatus::Solved, "{input:?}");
            max_passes = max_passes.max(sol.iterations);
            max_iter = max_iter.max(reference.iterations);
            for (a, c) in sol.thrust.iter().zip(reference.thrust.iter()) {
                worst_thrust = worst_thrust.max((a - c).abs());
            }
            let (ca, cc) = (scaled_cost(&sol, &params), scaled_cost(&reference, &params));
            worst_cost = worst_cost.max((ca - cc).abs() - (1e-8 + 1e-7 * cc.abs()));
            let [fx, fy, fzm, mx, my, mz] = input.foot_wrench;
            let [fz, wmx, wmy, wmz] = sol.foot_wrench;
            // Uncontrolled components equal the measurement (eq. 38 with U_mask).
            assert!((wmx - mx).abs() < TOL && (wmy - my).abs() < TOL && (wmz - mz).abs() < TOL);
            // Eq. (38): Q̄_perch,z λ = F_z,t + (F_z,t−1 − F̃_z).
            let produced: f64 = (0..2)
                .map(|i| input.foot_allocation[(0, i)] * sol.thrust[i])
                .sum();
            let target = fz + params.feedback_gain * (input.previous_foot_wrench[0] - fzm);
            assert!(
                (produced - target).abs() < 1e-5,
                "eq 38 residual {}",
                produced - target
            );
            assert!(fz >= params.epsilon_z - TOL); // (39)
            assert!(fx.abs() <= params.mu_x * fz + TOL); // (40)
            assert!(fy.abs() <= params.mu_y * fz + TOL);
            assert!(mz.abs() <= params.mu_z * fz + TOL); // (41)
            let px = (fx * params.zmp_z - my) / fz; // (43)
            let py = (fy * params.zmp_z + mx) / fz; // (44)
            assert!(px.abs() <= params.half_size_x + TOL && py.abs() <= params.half_size_y + TOL);
            for i in 0..4 {
                // (48)
                assert!((sol.thrust[i] - input.previous_thrust[i]).abs() <= 5.0 + 1e-9);
            }
        } else if margin >= -1e-3 {
            boundary_failures += usize::from(!sol.status.is_solution());
        } else {
            infeasible += 1;
            // Never "solved"; clearly infeasible ones carry Clarabel's certificate. Within a
            // few 0.01 N of feasibility the IPM may hit max_iter instead (still a safe command).
            // The active-set path proves infeasibility itself (Farkas) unless it is within
            // 1e-6 of feasible, where it hands over to Clarabel (and Clarabel's rule applies).
            let acceptable = sol.status == PerchStatus::Infeasible
                || (margin > -0.05 && sol.status == PerchStatus::MaxIterations);
            if !acceptable || (margin < -0.05 && sol.fallback) {
                wrong_infeasible.push((margin, sol.status));
            }
            let reference_ok = reference.status == PerchStatus::Infeasible
                || (margin > -0.05 && reference.status == PerchStatus::MaxIterations);
            if !reference_ok {
                wrong_infeasible.push((margin, reference.status));
            }
            assert_eq!(
                sol.thrust, reference.thrust,
                "same safe command from both paths"
            );
        }
    }
    assert!(
        wrong_infeasible.is_empty(),
        "infeasible instances not reported: {wrong_infeasible:?}"
    );
    let counters = qp.counters();
    assert_eq!(counters.failures() as usize, infeasible + boundary_failures);
    assert!(
        worst_thrust <= THRUST_AGREEMENT,
        "active set vs Clarabel: {worst_thrust} N"
    );
    assert!(worst_cost <= 0.0, "cost beyond tolerance by {worst_cost}");
    eprintln!(
        "perch_random: {feasible} feasible solved, {infeasible} infeasible detected, \
         active set max {max_passes} passes, {} fallbacks, Clarabel max {max_iter} iterations, \
         worst thrust difference {worst_thrust:.2e} N, {:.1} s",
        counters.fallbacks(),
        started.elapsed().as_secs_f64()
    );
}

/// Beyond Table VII: random weights `N` (0.05..1, so `min P_ii ≥ 0.05` and the agreement
/// bound of the module doc grows by `√(1/0.05)`), random wrench masks (F_z always
/// controlled), every rotor perching and `p_ZMP_z ≠ 0`. No analytic feasibility check exists
/// here, so Clarabel is the reference: same status class, and thrusts within the bound.
#[test]
fn general_parameters_agree_with_clarabel() {
    let mut rng = ChaCha8Rng::seed_from_u64(0x5EED_0002);
    let count = (instance_count() / 5).max(1000);
    let (mut solved, mut infeasible, mut fallbacks) = (0usize, 0usize, 0u64);
    let mut worst = 0.0_f64;
    for block in 0..count / 100 {
        use rand::Rng;
        let mut params = PerchParams {
            weight: [0; 4].map(|_| rng.random_range(0.05..1.0)),
            wrench_mask: [true, block % 2 == 0, block % 3 == 0, block % 5 == 0],
            perch_rotors: [true; 4],
            zmp_z: rng.random_range(-0.05..0.05),
            relax_rate_limit: false,
            ..PerchParams::default()
        };
        let mut qp = PerchQp::new(params.clone()).unwrap();
        params.solver = PerchSolver::Clarabel;
        let mut clarabel = PerchQp::new(params.clone()).unwrap();
        let min_w = params.weight.iter().fold(f64::INFINITY, |a, b| a.min(*b));
        let max_w = params.weight.iter().fold(0.0_f64, |a, b| a.max(*b));
        let bound = THRUST_AGREEMENT * (max_w / min_w).sqrt();
        for _ in 0..100 {
            let input = random_instance(&mut rng, &params);
            let sol = qp.solve(&input);
            let reference = clarabel.solve(&input);
            match reference.status {
                PerchStatus::Solved => {
                    assert!(sol.status.is_solution(), "{:?} vs solved", sol.status);
                    solved += 1;
                    for (a, c) in sol.thrust.iter().zip(reference.thrust.iter()) {
                        let d = (a - c).abs();
                        worst = worst.max(d / bound * THRUST_AGREEMENT);
                        assert!(d <= bound, "{d} N > {bound} N on {input:?} / {params:?}");
                    }
                }
                PerchStatus::Infeasible => {
                    infeasible += 1;
                    assert!(!sol.status.is_solution(), "solved an infeasible instance");
                }
                _ => {} // near the feasibility boundary: either answer is acceptable
            }
        }
        fallbacks += qp.counters().fallbacks();
    }
    assert!(
        solved > count / 10 && infeasible > count / 20,
        "{solved} {infeasible}"
    );
    eprintln!(
        "general params: {solved} solved, {infeasible} infeasible, {fallbacks} fallbacks, \
         worst normalised thrust difference {worst:.2e} N"
    );
}
