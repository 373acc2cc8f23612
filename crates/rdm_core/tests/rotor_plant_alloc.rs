//! Proves that the plant's per-step rotor work (ESC lag, ceiling ratio, rotor controls)
//! allocates nothing after setup: a counting global allocator wraps the system allocator
//! while it runs over ordinary, capped, NaN, infinite and out-of-range inputs.

use std::alloc::System;

use rdm_core::sim::esc_duty::EscDuty;
use rdm_core::sim::json_text::push_ascii_json_string;
use rdm_core::sim::rotor_plant::{CeilingRatio, RotorPlant};
use stats_alloc::{Region, StatsAlloc, INSTRUMENTED_SYSTEM};

#[global_allocator]
static GLOBAL: &StatsAlloc<System> = &INSTRUMENTED_SYSTEM;

#[test]
fn rotor_step_allocates_nothing() {
    let mut plant = RotorPlant::new(&[1, 3, 4, 6], &[2, 3, 4, 5], Some(0.75));
    let mut bad = RotorPlant::new(&[1, 30], &[0, 1], Some(0.75));
    for i in 0..4 {
        plant.set_alpha(i, 0.02);
        plant.set_target(i, 5.0 + i as f64);
    }
    plant.set_ceiling(0, CeilingRatio::parametric(0.0635, 4.7, 0.8, 1.5));
    plant.set_ceiling(1, CeilingRatio::parametric(0.2, 0.05, 0.8, 1.5));
    plant.set_ceiling(2, CeilingRatio::Unity);
    plant.set_ceiling(3, CeilingRatio::parametric(0.1, 4.7, 0.8, 1.2));
    let specials = [
        0.0,
        -0.0,
        0.7,
        2.0,
        f64::NAN,
        f64::INFINITY,
        f64::NEG_INFINITY,
        1e-7,
    ];
    let mut xpos = [0.0; 8 * 3];
    let mut xmat = [0.0; 8 * 9];
    let mut ctrl = [0.0; 7];
    let mut escs = [EscDuty::new(0.0798, -6.63, 12.36, 20.0, 1.2); 4];
    // Capacity for every string below: pushing into it must not reallocate.
    let mut text = String::with_capacity(4096);
    let region = Region::new(GLOBAL);
    let mut checksum = 0.0;
    for k in 0..5000usize {
        for s in 0..8 {
            xpos[s * 3 + 2] = 0.5 + 0.3 * (k as f64 * 0.01 + s as f64).sin();
            xmat[s * 9 + 8] = specials[(k + s) % specials.len()].min(1.0);
        }
        xpos[3 * 3 + 2] = specials[k % specials.len()];
        for (i, e) in escs.iter_mut().enumerate() {
            let target = e.command(0.45 + 0.1 * specials[(k + i) % specials.len()]);
            plant.set_target(i, target);
        }
        if k % 500 == 0 {
            text.clear();
            push_ascii_json_string("perched \u{e9}\"\n\u{1F600}", &mut text);
        }
        plant.step(&xpos, &xmat, &mut ctrl);
        let _ = bad.step(&xpos, &xmat, &mut ctrl);
        checksum += plant
            .applied()
            .iter()
            .filter(|v| v.is_finite())
            .sum::<f64>();
    }
    let stats = region.change();
    assert_eq!(stats.allocations, 0, "allocations: {stats:?}");
    assert_eq!(stats.reallocations, 0);
    assert!(checksum > 0.0);
}
