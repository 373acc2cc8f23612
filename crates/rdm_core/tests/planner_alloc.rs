//! A planner step (levelling, finite-difference constraint rows, task Jacobians, QP
//! assembly, Clarabel) allocates nothing of its own after setup: a counting global
//! allocator wraps the system one. This binary has a single test (harness = false).

use std::alloc::System;

use nalgebra::Vector3;
use rdm_core::model::RobotDescription;
use rdm_core::planner::{
    EeOrientation, Mode, Planner, PlannerConfig, ShapePair, ShapeSpec, StepStatus,
};
use stats_alloc::{Region, StatsAlloc, INSTRUMENTED_SYSTEM};

#[global_allocator]
static GLOBAL: &StatsAlloc<System> = &INSTRUMENTED_SYSTEM;

const URDF: &str = include_str!("../../../python/rdm/data/robots/rdm/rdm.urdf");
const TOML: &str = include_str!("../../../python/rdm/data/robots/rdm/rdm.toml");

fn planner_step_allocates_only_in_clarabel_timers() {
    let robot = RobotDescription::from_strs(URDF, TOML, "rdm.urdf", "rdm.toml").unwrap();
    let link = |name: &str| robot.links.iter().position(|l| l.name == name).unwrap();
    let mut cfg = PlannerConfig::new(Mode::Perched);
    cfg.shapes = vec![
        ShapeSpec::Capsule {
            link: link("root_link"),
            a: [0.0; 3],
            b: [0.4, 0.0, 0.0],
            radius: 0.02,
        },
        ShapeSpec::Capsule {
            link: link("end_link"),
            a: [0.0; 3],
            b: [0.25, 0.0, 0.0],
            radius: 0.015,
        },
        ShapeSpec::Sphere {
            link: link("arm_unit_pitch"),
            center: [0.0, 0.0, 0.03],
            radius: 0.1335,
        },
    ];
    cfg.pairs = vec![
        ShapePair::Shapes(0, 1),
        ShapePair::Shapes(2, 0),
        ShapePair::Ceiling(1),
    ];
    let mut zeta = vec![0.0; 6 + robot.n_q()];
    zeta[6..12].copy_from_slice(&[1.2, 0.8, 0.0, -0.9, 0.0, 0.0]);
    let mut planner = Planner::new(robot, cfg, &zeta).unwrap();
    let start = planner.zeta().to_vec();
    let target = [0.2, -0.3, -0.7];
    // Warm-up step: Clarabel's timer map gets its entries on the first solve.
    planner.step(&target, &EeOrientation::Free).unwrap();

    let region = Region::new(GLOBAL);
    let mut moved = 0usize;
    let mut rejected = 0usize;
    for k in 0..200 {
        if k % 50 == 0 {
            planner.set_zeta(&start).unwrap();
            // A NaN target is rejected before any work, without allocating.
            if planner
                .step(&[f64::NAN, 0.0, 0.0], &EeOrientation::Free)
                .is_err()
            {
                rejected += 1;
            }
        }
        // every other step toward a tool axis (the 5-D target), alike without allocating
        let orientation = if k % 2 == 0 {
            EeOrientation::Free
        } else {
            EeOrientation::Axis(Vector3::new(0.3, 0.0, -1.0))
        };
        if let Ok(r) = planner.step(&target, &orientation) {
            if r.status == StepStatus::Moved {
                moved += 1;
            }
        }
    }
    let change = region.change();
    let allocations = change.allocations + change.reallocations;
    assert_eq!(rejected, 4);
    assert!(moved > 150, "{moved} steps moved");
    // One Clarabel timer allocation per solve (see tests/perch_alloc.rs), nothing else.
    assert_eq!(allocations, 200, "{allocations} allocations in 200 steps");
    assert!(
        change.bytes_deallocated >= change.bytes_allocated,
        "net growth: {change:?}"
    );
}

// Runs as a plain `main` (harness = false): the allocation counter is process-global.
fn main() {
    planner_step_allocates_only_in_clarabel_timers();
    println!("planner_alloc: ok");
}
