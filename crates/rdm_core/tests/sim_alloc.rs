//! Proves that the per-sample sensor models and the Leptrino frame encoder allocate nothing:
//! a counting global allocator wraps the system allocator while they run over ordinary,
//! saturated, non-finite and unencodable inputs.

use std::alloc::System;

use rdm_core::sim::leptrino_stream::{encode_force_frame, ok_sample_run};
use rdm_core::sim::sensor_noise::{ImuNoiseModel, WrenchNoiseModel};
use stats_alloc::{Region, StatsAlloc, INSTRUMENTED_SYSTEM};

#[global_allocator]
static GLOBAL: &StatsAlloc<System> = &INSTRUMENTED_SYSTEM;

/// One test: the allocator's counters are global, and the test harness would run a second
/// test (and its own bookkeeping) on another thread while a region is measured.
#[test]
fn sim_models_allocate_nothing() {
    sensor_models_and_frame_encoder_allocate_nothing();
    plate_contact_measure_allocates_nothing();
}

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

fn plate_contact_measure_allocates_nothing() {
    use rdm_core::sim::plate_contact::{yaw_about, ContactRow, PlateContactModel};
    // set up (allocates): plate body 1, ceiling geom 0, arm geom 2
    let model = PlateContactModel::new(vec![0, 1, 2], vec![true, false, false], 1);
    let efc: Vec<f64> = (0..24).map(|i| (i as f64 * 0.7).cos() * 5.0).collect();
    let rot = [0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0];
    let region = Region::new(GLOBAL);
    let mut points = 0usize;
    let mut checksum = 0.0;
    for k in 0..2000usize {
        let rows = (0..4i32).map(|i| ContactRow {
            geom: if i == 3 { [2, 0] } else { [i % 2, 1 - i % 2] },
            frame: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
            pos: [0.01 * f64::from(i), -0.02, 1.6],
            efc_address: if k % 7 == 0 && i == 1 { -1 } else { i * 4 },
            dim: 4,
            friction: [1.0, 1.0, 0.005, 0.0001, 0.0001],
        });
        if let Ok(m) = model.measure(rows, &efc, [0.0, 0.0, 1.6], &rot, k % 2 == 0) {
            points += m.points;
            checksum += m.force[0] + m.zmp[1];
        }
        checksum += yaw_about(&rot, &rot).unwrap_or(0.0);
        // an out-of-range row is an error value, not an allocation
        let bad = [ContactRow {
            geom: [0, 9],
            frame: [0.0; 9],
            pos: [0.0; 3],
            efc_address: 0,
            dim: 3,
            friction: [0.0; 5],
        }];
        assert!(model.measure(bad, &efc, [0.0; 3], &rot, false).is_err());
    }
    let stats = region.change();
    assert_eq!(stats.allocations, 0, "allocations: {stats:?}");
    assert_eq!(stats.reallocations, 0);
    assert_eq!(points, 2000 * 3);
    assert!(checksum.is_finite());
}
