//! Shared by the Spinal tests and the `spinal_step` bench: one example gain set, so the
//! bench measures the same controller the allocation test proves allocation-free.

use rdm_core::control::gains::{GainSet, PidGains, RotorGains};

/// Roll/pitch P-I-D and yaw D on every rotor (values of the order the LQI produces).
pub fn example_gains() -> GainSet {
    let rotor = RotorGains {
        roll: PidGains {
            p: 3.0,
            i: 0.5,
            d: 0.8,
        },
        pitch: PidGains {
            p: 3.0,
            i: 0.5,
            d: 0.8,
        },
        yaw: PidGains {
            p: 0.0,
            i: 0.0,
            d: 0.4,
        },
        z: PidGains::default(),
    };
    let mut set = GainSet::default();
    for g in set.iter_mut().take(4) {
        *g = rotor;
    }
    set
}
