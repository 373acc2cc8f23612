//! Proves that the Spinal real-time steps allocate nothing after setup: a counting global
//! allocator wraps the system allocator and the steps run many times inside a region.

mod spinal_common;

use std::alloc::System;

use spinal_common::example_gains;

use rdm_core::control::attitude::{
    AttitudeControlConfig, AttitudeController, SpinalConfig, SpinalStep,
};
use rdm_core::estimate::{AttitudeEstimator, EstimatorConfig, ImuSample};
use rdm_core::pwm::PwmInfo;
use stats_alloc::{Region, StatsAlloc, INSTRUMENTED_SYSTEM};

#[global_allocator]
static GLOBAL: &StatsAlloc<System> = &INSTRUMENTED_SYSTEM;

fn sample(k: usize) -> ImuSample {
    let t = k as f64 * 0.005;
    ImuSample {
        gyro: [0.1 * t.sin(), -0.05 * t.cos(), 0.02],
        acc: [0.3 * t.sin(), -0.2, 9.8],
        mag: [30.0 + (k % 7) as f64, 2.0, -40.0],
    }
}

fn arm(controller: &mut AttitudeController) {
    controller.set_uav_info(4, 16).unwrap();
    controller.set_pwm_info(PwmInfo::hydrus_example()).unwrap();
    controller.set_gains(&example_gains()).unwrap();
    controller
        .set_pinv_inertia(&[[0.5, 0.5, 0.2]; 4], [0.1, 0.1, 0.2, 0.0, 0.0, 0.0])
        .unwrap();
    controller.flight_config(0, 0.0).unwrap();
    controller.flight_config(160, 0.0).unwrap();
}

fn assert_no_allocations<F: FnMut(usize)>(what: &str, mut f: F) {
    // Warm up outside the region (first-call lazies), then count.
    f(0);
    let region = Region::new(GLOBAL);
    for k in 1..5000 {
        f(k);
    }
    let stats = region.change();
    assert_eq!(
        (
            stats.allocations,
            stats.reallocations,
            stats.bytes_allocated
        ),
        (0, 0, 0),
        "{what} allocated: {stats:?}"
    );
}

/// The global counters are process-wide, so the three checks run in one test (one thread).
fn spinal_steps_allocate_nothing_after_setup() {
    // Let the test harness finish its own start-up allocations on the main thread.
    std::thread::sleep(std::time::Duration::from_millis(200));
    estimator_step_allocates_nothing();
    attitude_step_and_messages_allocate_nothing();
    spinal_step_allocates_nothing();
}

fn estimator_step_allocates_nothing() {
    let mut estimator = AttitudeEstimator::new(EstimatorConfig::default()).unwrap();
    assert_no_allocations("estimator", |k| {
        let mut s = sample(k);
        if k.is_multiple_of(100) {
            s.gyro[0] = f64::NAN; // the error path too
        }
        if k.is_multiple_of(101) {
            s.gyro[1] = 1e8; // out of range: the guard's rejection
        }
        if (2000..2400).contains(&k) {
            s.gyro[0] = 34.9; // a full-scale spin: rescaling, degraded, re-initialisation
        }
        std::hint::black_box(estimator.step(&s));
    });
    let c = estimator.counters();
    assert!(c.out_of_range > 0 && c.rescaled_vectors > 0 && c.degraded_steps > 0);
}

fn attitude_step_and_messages_allocate_nothing() {
    let mut controller = AttitudeController::new(AttitudeControlConfig::default()).unwrap();
    arm(&mut controller);
    let rotation = nalgebra::Matrix3::identity();
    assert_no_allocations("attitude controller", |k| {
        let now = k as f64 * 0.005;
        if k.is_multiple_of(5) {
            let _ = controller.four_axis_command([0.01, -0.02, 0.1], &[5.0, 5.0, 5.0, 5.0], now);
            let _ = controller.four_axis_command([0.0, 0.0, 0.0], &[5.0, 5.0], now); // rejected
            let _ = controller.set_gains(&example_gains());
        }
        if k.is_multiple_of(7) {
            let _ = controller.four_axis_command([0.0, 0.0, -1e30], &[3.4e38, -1.0, 5.0, 5.0], now);
        }
        // The guards: a huge rate (non-finite thrust), implausible voltages.
        let rate = if k.is_multiple_of(11) { 1e300 } else { 0.1 };
        let gyro = nalgebra::Vector3::new(rate, rate, 0.05);
        let voltage = if k.is_multiple_of(300) { 1.75 } else { 24.0 };
        std::hint::black_box(controller.step(now, &rotation, &gyro, voltage));
    });
    let c = controller.counters();
    assert!(c.non_finite_outputs > 0 && c.saturated_commands > 0 && c.rejected_voltages > 0);
}

fn spinal_step_allocates_nothing() {
    let mut spinal = SpinalStep::new(SpinalConfig::default()).unwrap();
    arm(spinal.controller_mut());
    assert_no_allocations("SpinalStep", |k| {
        let now = k as f64 * 0.005;
        if k.is_multiple_of(5) {
            let _ = spinal
                .controller_mut()
                .four_axis_command([0.0, 0.0, 0.0], &[6.0; 4], now);
        }
        std::hint::black_box(spinal.step(now, &sample(k), 24.5));
    });
}

// Runs as a plain `main` (harness = false): the allocation counter is process-global, and
// libtest's own threads would otherwise allocate while a step is being counted.
fn main() {
    spinal_steps_allocate_nothing_after_setup();
    println!("spinal_alloc: ok");
}
