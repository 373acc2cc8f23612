//! Zero heap allocations per synthesis (cold and warm) and per position step.

mod lqi_common;

use std::alloc::System;

use stats_alloc::{Region, StatsAlloc, INSTRUMENTED_SYSTEM};

use lqi_common::{perturb, random_robot, random_robot_with, rng};
use nalgebra::{Matrix3, Vector2, Vector3};
use rdm_core::control::lqi::{
    flight_thrust, GyroCompensation, LqiConfig, LqiState, LqiSynthesizer, PcAxisController,
    PcAxisErrors, RotorVector,
};
use rdm_core::control::position::{PositionController, PositionGains, PositionInput};

#[global_allocator]
static GLOBAL: &StatsAlloc<System> = &INSTRUMENTED_SYSTEM;

fn count<T>(f: impl FnOnce() -> T) -> (T, usize) {
    let region = Region::new(GLOBAL);
    let out = f();
    let change = region.change();
    (out, change.allocations + change.reallocations)
}

// Runs as a plain `main` (harness = false): the counter is process-global, and libtest's
// own threads would otherwise allocate while a step is being counted.
fn main() {
    steps_do_not_allocate();
    other_rotor_counts_do_not_allocate();
    println!(
        "lqi_alloc: zero allocations per step (cold, warm, error path, eq. 29, PC axes, position; \
         4, 6 and 8 rotors)"
    );
}

/// Six and eight rotors (the count fixed at construction): synthesis and eq. (29) allocate
/// nothing either.
fn other_rotor_counts_do_not_allocate() {
    let mut rng = rng(6);
    for rotors in [6, 8] {
        let robot = random_robot_with(&mut rng, rotors);
        let moved = perturb(&mut rng, &robot, 0.02);
        let mut synthesizer = LqiSynthesizer::new(LqiConfig::for_rotors(rotors)).unwrap();
        for (m, i, a) in [&robot, &moved] {
            let (result, n) = count(|| synthesizer.synthesize(*m, i, a).map(|g| g.report));
            result.expect("synthesis");
            assert_eq!(n, 0, "{rotors}-rotor synthesis allocated");
        }
        let k = synthesizer.last().unwrap().k;
        let (thrust, n) = count(|| {
            let gyro = GyroCompensation::new(&moved.2, &moved.1, rotors)?;
            flight_thrust(
                &k,
                &LqiState::from_element(0.01),
                &gyro,
                &Vector3::new(0.1, -0.2, 0.3),
            )
        });
        thrust.expect("eq. 29");
        assert_eq!(n, 0, "{rotors}-rotor eq. (29) allocated");
    }
}

fn steps_do_not_allocate() {
    let mut rng = rng(5);
    let robot = random_robot(&mut rng);
    let moved = perturb(&mut rng, &robot, 0.02);
    let mut synthesizer = LqiSynthesizer::new(LqiConfig::default()).unwrap();

    let (cold, n) = count(|| {
        synthesizer
            .synthesize(robot.0, &robot.1, &robot.2)
            .map(|g| g.report)
    });
    cold.expect("cold");
    assert_eq!(n, 0, "cold synthesis allocated");
    let (warm, n) = count(|| {
        synthesizer
            .synthesize(moved.0, &moved.1, &moved.2)
            .map(|g| g.report)
    });
    warm.expect("warm");
    assert_eq!(n, 0, "warm synthesis allocated");
    let (bad, n) = count(|| {
        synthesizer
            .synthesize(f64::NAN, &moved.1, &moved.2)
            .is_err()
    });
    assert!(bad);
    assert_eq!(n, 0, "error path allocated");

    let k = synthesizer.last().unwrap().k;
    let gains = synthesizer.last().unwrap().gains;
    let (thrust, n) = count(|| {
        let gyro = GyroCompensation::new(&moved.2, &moved.1, 4)?;
        flight_thrust(
            &k,
            &LqiState::from_element(0.01),
            &gyro,
            &Vector3::new(0.1, -0.2, 0.3),
        )
    });
    thrust.expect("eq. 29");
    assert_eq!(n, 0, "eq. (29) allocated");

    let mut pc = PcAxisController::new();
    let errors = PcAxisErrors {
        z: 0.1,
        z_rate: 0.0,
        yaw: 0.05,
    };
    let (cmd, n) = count(|| pc.step(&gains, &errors, &RotorVector::zeros(), 0.025));
    cmd.expect("pc axes");
    assert_eq!(n, 0, "PC axes step allocated");

    let mut position = PositionController::new(PositionGains::table_v()).unwrap();
    let input = PositionInput {
        position: Vector2::new(0.1, -0.2),
        velocity: Vector2::new(0.0, 0.1),
        target_position: Vector2::zeros(),
        target_velocity: Vector2::zeros(),
        target_yaw: 0.3,
        link_rotations: [Matrix3::identity(); 2],
        dt: 0.025,
    };
    let (out, n) = count(|| position.step(&input));
    out.expect("position");
    assert_eq!(n, 0, "position step allocated");
}
