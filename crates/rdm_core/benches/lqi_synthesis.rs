//! LQI gain synthesis timing: cold (sign function), warm (Kleinman from the previous
//! configuration's gains), and the position step. Targets (reported, not asserted):
//! median <= 100 us and >= 5x faster than scipy's solve_continuous_are.

#[path = "../tests/lqi_common/mod.rs"]
mod lqi_common;

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion};
use nalgebra::{Matrix3, Vector2};
use rdm_core::control::lqi::{LqiConfig, LqiSynthesizer};
use rdm_core::control::position::{PositionController, PositionGains, PositionInput};

fn synthesis(c: &mut Criterion) {
    let mut rng = lqi_common::rng(42);
    let robot = lqi_common::random_robot(&mut rng);
    let moved = lqi_common::perturb(&mut rng, &robot, 0.02);

    c.bench_function("lqi_synthesis_cold_sign", |bench| {
        let mut s = LqiSynthesizer::new(LqiConfig::default()).expect("weights");
        bench.iter(|| {
            s.reset();
            let g = s.synthesize(black_box(robot.0), black_box(&robot.1), black_box(&robot.2));
            black_box(g.map(|g| g.k).expect("cold"))
        })
    });

    c.bench_function("lqi_synthesis_warm_kleinman", |bench| {
        let mut s = LqiSynthesizer::new(LqiConfig::default()).expect("weights");
        s.synthesize(robot.0, &robot.1, &robot.2).expect("setup");
        let mut flip = false;
        bench.iter(|| {
            // Alternate between two neighbouring configurations, as joint motion does.
            flip = !flip;
            let r = if flip { &moved } else { &robot };
            let g = s.synthesize(black_box(r.0), black_box(&r.1), black_box(&r.2));
            black_box(g.map(|g| g.k).expect("warm"))
        })
    });

    c.bench_function("position_step", |bench| {
        let mut p = PositionController::new(PositionGains::table_v()).expect("gains");
        let input = PositionInput {
            position: Vector2::new(0.1, -0.2),
            velocity: Vector2::new(0.0, 0.1),
            target_position: Vector2::zeros(),
            target_velocity: Vector2::zeros(),
            target_yaw: 0.3,
            link_rotations: [Matrix3::identity(); 2],
            dt: 0.025,
        };
        bench.iter(|| black_box(p.step(black_box(&input)).expect("step")))
    });
}

criterion_group!(benches, synthesis);
criterion_main!(benches);
