//! The model's loop-time calls allocate nothing after setup (counting global allocator).

use std::alloc::System;

use nalgebra::{Isometry3, Vector3};
use rdm_core::model::{
    allocation_bar, base_pose_from_zeta, Matrix4xN, Matrix6xN, ModelWorkspace, RobotDescription,
    StaticLoads,
};
use stats_alloc::{Region, StatsAlloc, INSTRUMENTED_SYSTEM};

#[global_allocator]
static GLOBAL: &StatsAlloc<System> = &INSTRUMENTED_SYSTEM;

fn evaluation_and_queries_do_not_allocate() {
    let robot = RobotDescription::from_strs(
        include_str!("../../../python/rdm/data/robots/rdm/rdm.urdf"),
        include_str!("../../../python/rdm/data/robots/rdm/rdm.toml"),
        "rdm.urdf",
        "rdm.toml",
    )
    .unwrap();
    let mut ws = ModelWorkspace::new(&robot);
    let mut jac = Matrix6xN::zeros(6 + robot.n_q());
    let mut q_bar = Matrix4xN::zeros(robot.n_rotors());
    let mut tau = vec![0.0; robot.n_q()];
    let mut grad = vec![0.0; 6 + robot.n_q()];
    let ee = robot.frame("end_effector").unwrap();
    let cog = robot.frame("cog").unwrap();
    let thrusts = [8.0; 4];
    let loads = StaticLoads {
        thrusts: &thrusts,
        foot_wrench: &[0.0; 6],
        end_effector_wrench: &[1.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        gravity: &[0.0, 0.0, -9.80665],
    };
    let q = [0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0];
    let base = base_pose_from_zeta(&Vector3::new(0.1, 0.2, 0.3), &Vector3::new(0.1, -0.2, 0.3));
    robot.evaluate(&q, &base, &mut ws).unwrap(); // warm-up

    let region = Region::new(GLOBAL);
    for _ in 0..10 {
        robot.evaluate(&q, &base, &mut ws).unwrap();
        robot.frame_jacobian(&ws, ee, &mut jac).unwrap();
        robot.frame_jacobian(&ws, cog, &mut jac).unwrap();
        assert!(allocation_bar(&ws, &mut q_bar));
        robot.static_torques(&ws, &loads, &mut tau).unwrap();
        robot.aerial_zmp(&mut ws).unwrap();
        robot.aerial_zmp_from_thrusts(&mut ws, &thrusts).unwrap();
        robot.stability(&ws).unwrap();
        robot
            .stability_gradient(&q, &Isometry3::identity(), &mut ws, &mut grad)
            .unwrap();
        robot.foot_in_cog(&ws).unwrap();
        robot.unit_parent_rotation(&ws, 1).unwrap();
        let _ = robot.evaluate(&[f64::NAN; 10], &base, &mut ws); // error path too
    }
    let change = region.change();
    assert_eq!(change.allocations + change.reallocations, 0, "{change:?}");
}

// Runs as a plain `main` (harness = false): the allocation counter is process-global, and
// libtest's own threads would otherwise allocate while a step is being counted.
fn main() {
    evaluation_and_queries_do_not_allocate();
    println!("model_no_alloc: ok");
}
