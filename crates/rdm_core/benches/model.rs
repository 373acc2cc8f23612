//! Cost of the model calls made in control/planning loops (shipped RDM).

use criterion::{criterion_group, criterion_main, Criterion};
use nalgebra::{Isometry3, Vector3};
use rdm_core::model::{
    base_pose_from_zeta, Matrix6xN, ModelWorkspace, RobotDescription, StaticLoads,
};
use std::hint::black_box;

fn bench(c: &mut Criterion) {
    let robot = RobotDescription::from_strs(
        include_str!("../../../python/rdm/data/robots/rdm/rdm.urdf"),
        include_str!("../../../python/rdm/data/robots/rdm/rdm.toml"),
        "rdm.urdf",
        "rdm.toml",
    )
    .expect("shipped RDM");
    let mut ws = ModelWorkspace::new(&robot);
    let q = [0.5, -0.5, 0.2, 0.8, 0.6, 0.0, 0.1, -0.2, 0.3, 0.4];
    let base = base_pose_from_zeta(&Vector3::new(0.1, 0.2, 1.0), &Vector3::new(0.05, -0.1, 0.3));
    let mut jac = Matrix6xN::zeros(16);
    let mut tau = [0.0; 10];
    let mut grad = [0.0; 16];
    let ee = robot.frame("end_effector").unwrap();
    c.bench_function("model/evaluate", |b| {
        b.iter(|| robot.evaluate(black_box(&q), &base, &mut ws).unwrap())
    });
    robot.evaluate(&q, &base, &mut ws).unwrap();
    c.bench_function("model/jacobian_end_effector", |b| {
        b.iter(|| robot.frame_jacobian(&ws, ee, &mut jac).unwrap())
    });
    let thrusts = [9.0; 4];
    let loads = StaticLoads {
        thrusts: &thrusts,
        foot_wrench: &[0.0; 6],
        end_effector_wrench: &[0.0; 6],
        gravity: &[0.0, 0.0, -9.80665],
    };
    c.bench_function("model/static_torques", |b| {
        b.iter(|| robot.static_torques(&ws, &loads, &mut tau).unwrap())
    });
    c.bench_function("model/aerial_zmp", |b| {
        b.iter(|| robot.aerial_zmp(&mut ws).unwrap())
    });
    c.bench_function("model/stability_gradient", |b| {
        b.iter(|| {
            robot
                .stability_gradient(&q, &Isometry3::identity(), &mut ws, &mut grad)
                .unwrap()
        })
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
