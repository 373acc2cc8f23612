//! Criterion benchmark of the Spinal mirror's 200 Hz step (estimator + attitude control +
//! PWM conversion), armed and flying. Target (reported, not asserted): median <= 2 us.

#[path = "../tests/spinal_common/mod.rs"]
mod spinal_common;

use criterion::{criterion_group, criterion_main, Criterion};
use rdm_core::control::attitude::{SpinalConfig, SpinalStep};
use rdm_core::estimate::ImuSample;
use rdm_core::pwm::PwmInfo;
use spinal_common::example_gains;

fn armed_spinal() -> SpinalStep {
    let mut spinal = SpinalStep::new(SpinalConfig::default()).expect("config");
    let gains = example_gains();
    let c = spinal.controller_mut();
    c.set_uav_info(4, 16).expect("uav_info");
    c.set_pwm_info(PwmInfo::hydrus_example()).expect("pwm info");
    c.set_gains(&gains).expect("gains");
    c.set_pinv_inertia(&[[0.5, 0.5, 0.2]; 4], [0.1, 0.1, 0.2, 0.0, 0.0, 0.0])
        .expect("pinv");
    c.flight_config(0, 0.0).expect("arm");
    c.flight_config(160, 0.0).expect("integrate");
    spinal
}

fn bench(c: &mut Criterion) {
    let mut spinal = armed_spinal();
    let mut k: u64 = 0;
    c.bench_function("spinal_step", |b| {
        b.iter(|| {
            k += 1;
            let now = k as f64 * 0.005;
            let t = now.sin();
            if k.is_multiple_of(5) {
                let _ =
                    spinal
                        .controller_mut()
                        .four_axis_command([0.01, 0.0, 0.05], &[6.0; 4], now);
            }
            let imu = ImuSample {
                gyro: [0.1 * t, -0.05, 0.02],
                acc: [0.3 * t, -0.2, 9.8],
                mag: [30.0 + (k % 3) as f64, 2.0, -40.0],
            };
            std::hint::black_box(spinal.step(now, std::hint::black_box(&imu), 24.5))
        })
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
