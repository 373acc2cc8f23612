//! Time of one 40 Hz perching tick (filter + eq. 49) on random instances, with the default
//! active-set solver and with Clarabel.
//! Criterion reports the mean/median; the extra pass prints median, p99 and p99.9 of
//! 100,000 individually timed ticks (targets: median <= 20 us, p99.9 <= 100 us).

#[path = "../tests/perch_common/mod.rs"]
#[allow(dead_code)]
mod perch_common;

use std::hint::black_box;
use std::time::Instant;

use criterion::{criterion_group, criterion_main, Criterion};
use perch_common::random_instance;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rdm_core::control::perch::{PerchController, PerchInput, PerchParams, PerchQp, PerchSolver};

const SOLVERS: [PerchSolver; 2] = [PerchSolver::ActiveSet, PerchSolver::Clarabel];

fn params(solver: PerchSolver) -> PerchParams {
    PerchParams {
        solver,
        ..PerchParams::default()
    }
}

fn inputs(n: usize) -> Vec<PerchInput> {
    let params = PerchParams::default();
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    (0..n).map(|_| random_instance(&mut rng, &params)).collect()
}

fn percentiles(solver: PerchSolver) {
    let inputs = inputs(100_000);
    let mut controller = PerchController::new(params(solver), 40.0, 1.0).unwrap();
    let mut times: Vec<f64> = Vec::with_capacity(inputs.len());
    for input in &inputs {
        let t0 = Instant::now();
        let s = controller.tick(
            &input.foot_wrench,
            &input.foot_allocation,
            &input.allocation,
            input.mass,
            None,
        );
        black_box(s);
        times.push(t0.elapsed().as_secs_f64() * 1e6);
    }
    times.sort_by(f64::total_cmp);
    let at = |q: f64| times[((times.len() - 1) as f64 * q) as usize];
    println!(
        "perch_tick controller ({}), {} ticks: median {:.2} us, p99 {:.2} us, p99.9 {:.2} us, max {:.2} us; {:?}",
        solver.as_str(),
        times.len(),
        at(0.5),
        at(0.99),
        at(0.999),
        at(1.0),
        controller.counters()
    );
}

fn bench(c: &mut Criterion) {
    for solver in SOLVERS {
        percentiles(solver);
    }
    let inputs = inputs(1024);
    let mut k = 0usize;
    for solver in SOLVERS {
        let mut qp = PerchQp::new(params(solver)).unwrap();
        c.bench_function(&format!("perch_qp_solve/{}", solver.as_str()), |b| {
            b.iter(|| {
                k = (k + 1) % inputs.len();
                black_box(qp.solve(black_box(&inputs[k])))
            })
        });
    }
    for solver in SOLVERS {
        let mut controller = PerchController::new(params(solver), 40.0, 1.0).unwrap();
        c.bench_function(&format!("perch_controller_tick/{}", solver.as_str()), |b| {
            b.iter(|| {
                k = (k + 1) % inputs.len();
                let input = &inputs[k];
                black_box(controller.tick(
                    &input.foot_wrench,
                    &input.foot_allocation,
                    &input.allocation,
                    input.mass,
                    None,
                ))
            })
        });
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
