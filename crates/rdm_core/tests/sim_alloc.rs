//! Proves that the per-sample sensor models and the Leptrino frame encoder allocate nothing:
//! a counting global allocator wraps the system allocator while they run over ordinary,
//! saturated, non-finite and unencodable inputs.

use std::alloc::System;

use rdm_core::sim::leptrino_stream::{encode_force_frame, ok_sample_run};
use rdm_core::sim::sensor_noise::{ImuNoiseModel, WrenchNoiseModel};
use stats_alloc::{Region, StatsAlloc, INSTRUMENTED_SYSTEM};

#[global_allocator]
static GLOBAL: &StatsAlloc<System> = &INSTRUMENTED_SYSTEM;

#[test]
fn sensor_models_and_frame_encoder_allocate_nothing() {
    let rated = [100.0, 100.0, 200.0, 5.0, 5.0, 4.0];
    let wrench = WrenchNoiseModel::new(rated, [0.1; 6], 0.003, true, 10000.0);
    let imu = ImuNoiseModel {
        bias: [[0.01; 3], [0.05; 3], [1.0; 3]],
        std: [0.001, 0.03, 0.5],
        range: [34.9, 78.5],
        lsb: Some([0.001, 0.0024, 0.15]),
    };
    let specials = [
        0.0,
        -0.0,
        1e9,
        -1e9,
        f64::NAN,
        f64::INFINITY,
        f64::NEG_INFINITY,
        3.3,
    ];
    let region = Region::new(GLOBAL);
    let mut checksum = 0.0;
    let mut frames = 0usize;
    for k in 0..2000usize {
        let x = (k as f64 * 0.37).sin() * 150.0;
        let s = specials[k % specials.len()];
        let ideal = [x, -x, s, x * 0.01, s, -0.0];
        let normals = [0.5, -1.0, 2.0, s, 0.0, -0.3];
        let w = wrench.sample(&ideal, &normals);
        checksum += w.values[0] + w.saturated.iter().filter(|b| **b).count() as f64;
        let i = imu.sample(&[[x, s, 0.0], [x, 9.8, s], [s, 20.0, -x]], &[0.1; 9]);
        checksum += i.values[1][1];
        if let Ok(f) = encode_force_frame(&[x; 6], &rated, (k % 40000) as i64, 0, 0, 0) {
            frames += f.as_bytes().len();
            // host-side scan of the frame, whole and cut (a stack buffer, no allocation)
            let b = f.as_bytes();
            frames += ok_sample_run(b).count + ok_sample_run(&b[..b.len() / 2]).end;
        }
        let _ = encode_force_frame(&ideal, &rated, 250, 0, 0, 0);
    }
    let stats = region.change();
    assert_eq!(stats.allocations, 0, "allocations: {stats:?}");
    assert_eq!(stats.reallocations, 0);
    assert!(checksum.is_finite() || checksum.is_nan());
    assert!(frames > 0);
}
