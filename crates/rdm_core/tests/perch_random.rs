//! 100,000 seeded random perching QPs (count via `RDM_PERCH_INSTANCES`): every instance the
//! analytic check calls feasible is solved, satisfies eqs. (38)-(48), and every instance it
//! calls infeasible is reported infeasible with an in-bounds safe command.

mod perch_common;

use perch_common::{feasibility_margin, random_instance, thrust_max};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rdm_core::control::perch::{PerchParams, PerchQp, PerchStatus};

const TOL: f64 = 1e-6;

fn instance_count() -> usize {
    std::env::var("RDM_PERCH_INSTANCES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(100_000)
}

#[test]
fn random_feasible_instances_all_solve_and_satisfy_constraints() {
    let params = PerchParams::default();
    let mut qp = PerchQp::new(params.clone()).unwrap();
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
            max_iter = max_iter.max(sol.iterations);
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
            let acceptable = sol.status == PerchStatus::Infeasible
                || (margin > -0.05 && sol.status == PerchStatus::MaxIterations);
            if !acceptable {
                wrong_infeasible.push((margin, sol.status));
            }
        }
    }
    assert!(
        wrong_infeasible.is_empty(),
        "infeasible instances not reported: {wrong_infeasible:?}"
    );
    let counters = qp.counters();
    assert_eq!(counters.failures() as usize, infeasible + boundary_failures);
    eprintln!(
        "perch_random: {feasible} feasible solved, {infeasible} infeasible detected, \
         max {max_iter} iterations, {:.1} s",
        started.elapsed().as_secs_f64()
    );
}
