//! Time of one planner step (eqs. 50-70: levelling, finite-difference constraint rows,
//! analytic task Jacobians, QP assembly and the Clarabel solve) on the shipped RDM,
//! perched, with the collision shapes of `python/rdm/planner/shapes.py`. The extra pass
//! prints median and p99 of individually timed steps (target: median <= 1 ms).

use std::hint::black_box;
use std::time::Instant;

use criterion::{criterion_group, criterion_main, Criterion};
use rdm_core::model::RobotDescription;
use rdm_core::planner::{EeOrientation, Mode, Planner, PlannerConfig, ShapePair, ShapeSpec};

const URDF: &str = include_str!("../../../python/rdm/data/robots/rdm/rdm.urdf");
const TOML: &str = include_str!("../../../python/rdm/data/robots/rdm/rdm.toml");
/// `rdm.planner.core.PERCHED_START_Q` (q1..q6; unit angles are re-solved).
const START_Q: [f64; 6] = [1.2, 0.8, 0.0, -0.9, 0.0, 0.0];
const TARGETS: [[f64; 3]; 2] = [[0.2, -0.3, -0.7], [-0.4, 0.3, -0.3]];

fn link(robot: &RobotDescription, name: &str) -> usize {
    robot.links.iter().position(|l| l.name == name).unwrap()
}

fn planner() -> Planner {
    let robot = RobotDescription::from_strs(URDF, TOML, "rdm.urdf", "rdm.toml").unwrap();
    let mut cfg = PlannerConfig::new(Mode::Perched);
    let capsule = |name: &str, len: f64, radius: f64| ShapeSpec::Capsule {
        link: link(&robot, name),
        a: [0.0; 3],
        b: [len, 0.0, 0.0],
        radius,
    };
    let sphere = |name: &str| ShapeSpec::Sphere {
        link: link(&robot, name),
        center: [0.0, 0.0, 0.03],
        radius: 0.07 + 0.0635,
    };
    cfg.shapes = vec![
        capsule("root_link", 0.40, 0.02),
        capsule("middle_link", 0.40, 0.02),
        capsule("end_link", 0.25, 0.015),
        sphere("foot_unit_pitch"),
        sphere("arm_unit_pitch"),
    ];
    cfg.pairs = vec![
        ShapePair::Shapes(0, 2),
        ShapePair::Shapes(3, 2),
        ShapePair::Shapes(4, 0),
        ShapePair::Ceiling(1),
        ShapePair::Ceiling(2),
    ];
    let mut zeta = vec![0.0; 6 + robot.n_q()];
    zeta[6..12].copy_from_slice(&START_Q);
    Planner::new(robot, cfg, &zeta).unwrap()
}

/// Step toward alternating targets, restarting from the start every 40 steps so the
/// steps stay representative (moving, constraints active near the end).
fn run(planner: &mut Planner, start: &[f64], k: usize) {
    if k.is_multiple_of(40) {
        planner.set_zeta(start).unwrap();
    }
    let target = TARGETS[(k / 40) % TARGETS.len()];
    black_box(planner.step(&target, &EeOrientation::Free).ok());
}

fn percentiles() {
    let mut p = planner();
    let start = p.zeta().to_vec();
    let mut times = Vec::with_capacity(4000);
    for k in 0..4000 {
        let t0 = Instant::now();
        run(&mut p, &start, k);
        times.push(t0.elapsed().as_secs_f64() * 1e6);
    }
    times.sort_by(f64::total_cmp);
    let at = |q: f64| times[((times.len() as f64 - 1.0) * q) as usize];
    println!(
        "planner_step: median {:.0} us, p99 {:.0} us, max {:.0} us over {} steps",
        at(0.5),
        at(0.99),
        at(1.0),
        times.len()
    );
}

fn bench(c: &mut Criterion) {
    percentiles();
    let mut p = planner();
    let start = p.zeta().to_vec();
    let mut k = 0;
    c.bench_function("planner_step", |b| {
        b.iter(|| {
            run(&mut p, &start, k);
            k += 1;
        })
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
