//! The 40 Hz onboard tick: position step (eqs. 30-36) followed by the perching controller
//! tick (filter + eq. 49), timed together on random perching instances, once with the
//! default active-set solver and once with Clarabel. Targets (reported, not asserted): median <= 20 us, p99.9 <= 100 us.
//! Besides criterion's estimate, one pass of 100,000 individually timed ticks prints
//! median, p99, p99.9 and max.

#[path = "../tests/perch_common/mod.rs"]
#[allow(dead_code)]
mod perch_common;

use std::hint::black_box;
use std::time::Instant;

use criterion::{criterion_group, criterion_main, Criterion};
use nalgebra::{Matrix3, Vector2};
use perch_common::random_instance;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rdm_core::control::perch::{PerchController, PerchInput, PerchParams, PerchSolver};
use rdm_core::control::position::{PositionController, PositionGains, PositionInput};

fn inputs(n: usize) -> Vec<(PositionInput, PerchInput)> {
    let params = PerchParams::default();
    let mut rng = ChaCha8Rng::seed_from_u64(40);
    (0..n)
        .map(|k| {
            let phase = k as f64 * 0.0157;
            let position = PositionInput {
                position: Vector2::new(0.05 * phase.cos(), 0.05 * phase.sin()),
                velocity: Vector2::new(rng.random_range(-0.05..0.05), 0.01),
                target_position: Vector2::zeros(),
                target_velocity: Vector2::zeros(),
                target_yaw: 0.1 * phase.sin(),
                link_rotations: [Matrix3::identity(); 2],
                dt: 0.025,
            };
            (position, random_instance(&mut rng, &params))
        })
        .collect()
}

/// Position step + perching tick, as the onboard node runs them every 25 ms.
struct OnboardTick {
    position: PositionController,
    perch: PerchController,
}

impl OnboardTick {
    fn new(solver: PerchSolver) -> Self {
        let params = PerchParams {
            solver,
            ..PerchParams::default()
        };
        Self {
            position: PositionController::new(PositionGains::table_v()).expect("gains"),
            perch: PerchController::new(params, 40.0, 1.0).expect("params"),
        }
    }

    fn tick(&mut self, (position, perch): &(PositionInput, PerchInput)) -> bool {
        let p = self.position.step(position);
        let s = self.perch.tick(
            &perch.foot_wrench,
            &perch.foot_allocation,
            &perch.allocation,
            perch.mass,
            None,
        );
        black_box(&p);
        p.is_ok() && s.status.is_solution()
    }
}

fn percentiles(solver: PerchSolver) {
    let inputs = inputs(100_000);
    let mut onboard = OnboardTick::new(solver);
    let mut times: Vec<f64> = Vec::with_capacity(inputs.len());
    let mut failures = 0usize;
    for input in &inputs {
        let t0 = Instant::now();
        let ok = onboard.tick(black_box(input));
        times.push(t0.elapsed().as_secs_f64() * 1e6);
        failures += usize::from(!ok);
    }
    times.sort_by(f64::total_cmp);
    let at = |q: f64| times[((times.len() - 1) as f64 * q).round() as usize];
    println!(
        "tick_40hz ({}), {} ticks: median {:.2} us, p99 {:.2} us, p99.9 {:.2} us, max {:.2} us; \
         ticks without a QP solution (random instances, the filter and the rate limit make \
         some infeasible): {failures}, active-set fallbacks: {}",
        solver.as_str(),
        times.len(),
        at(0.5),
        at(0.99),
        at(0.999),
        at(1.0),
        onboard.perch.counters().fallbacks(),
    );
}

fn bench(c: &mut Criterion) {
    let solvers = [PerchSolver::ActiveSet, PerchSolver::Clarabel];
    for solver in solvers {
        percentiles(solver);
    }
    let inputs = inputs(1024);
    let mut k = 0usize;
    for solver in solvers {
        let mut onboard = OnboardTick::new(solver);
        c.bench_function(&format!("tick_40hz/{}", solver.as_str()), |b| {
            b.iter(|| {
                k = (k + 1) % inputs.len();
                black_box(onboard.tick(black_box(&inputs[k])))
            })
        });
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
