//! The LQI's pieces against values written out by hand: `Ā`, `B̄` of eq. (26) (with the
//! inertia inverted by LU, not the Cholesky factor the code uses), the K-to-GainSet mapping
//! of `jsk-wire-protocols.md` sec. 4 as an explicit index table, JSK `clampGain` and
//! `maxYawGainIndex` on hand-made gain sets, the weight and inertia checks, the messages.

use nalgebra::Matrix3;
use rdm_core::control::gains::GainSet;
use rdm_core::control::lqi::gain_map::max_yaw_gain_index;
use rdm_core::control::lqi::{
    augmented_input_matrix, augmented_state_matrix, clamp_gain, gain_set_from_k, Allocation,
    LqiConfig, LqiError, LqiSynthesizer, MAX_WIRE_GAIN,
};
use rdm_core::control::riccati::{CareError, GainMatrix};

fn argument(e: LqiError) -> &'static str {
    match e {
        LqiError::InvalidInput { argument } => argument,
        other => panic!("unexpected {other:?}"),
    }
}

#[test]
fn a_bar_is_four_double_integrators_with_integral_states() {
    // JSK order [z, ż, φ, φ̇, θ, θ̇, ψ, ψ̇, ∫z, ∫φ, ∫θ, ∫ψ]; eq. (25): v̇ = −C e.
    let ones = [(0, 1), (2, 3), (4, 5), (6, 7)];
    let minus = [(8, 0), (9, 2), (10, 4), (11, 6)];
    let a = augmented_state_matrix();
    for r in 0..12 {
        for c in 0..12 {
            let expected = if ones.contains(&(r, c)) {
                1.0
            } else if minus.contains(&(r, c)) {
                -1.0
            } else {
                0.0
            };
            assert_eq!(a[(r, c)], expected, "A[{r},{c}]");
        }
    }
}

#[test]
fn b_bar_rows_are_thrust_over_mass_and_inverse_inertia_moments() {
    let mass = 2.5;
    let inertia = Matrix3::new(0.08, 0.01, -0.004, 0.01, 0.12, 0.002, -0.004, 0.002, 0.2);
    let mut allocation = Allocation::zeros();
    let columns = [
        [1.0, 0.3, -0.2, 0.016],
        [0.98, -0.3, -0.25, -0.016],
        [0.95, -0.28, 0.22, 0.016],
        [1.0, 0.31, 0.2, -0.016],
    ];
    for (i, c) in columns.iter().enumerate() {
        for (k, v) in c.iter().enumerate() {
            allocation[(k, i)] = *v;
        }
    }
    let b = augmented_input_matrix(mass, &inertia, &allocation, 4).unwrap();
    let inverse = inertia.lu().try_inverse().unwrap();
    for (i, c) in columns.iter().enumerate() {
        let moment = nalgebra::Vector3::new(c[1], c[2], c[3]);
        let angular = inverse * moment;
        // z̈ row (JSK state 1) and φ̈, θ̈, ψ̈ rows (states 3, 5, 7); the others are zero.
        let expected = [
            0.0,
            c[0] / mass,
            0.0,
            angular.x,
            0.0,
            angular.y,
            0.0,
            angular.z,
            0.0,
            0.0,
            0.0,
            0.0,
        ];
        for (r, e) in expected.iter().enumerate() {
            assert!(
                (b[(r, i)] - e).abs() < 1e-12,
                "B[{r},{i}] {} vs {e}",
                b[(r, i)]
            );
        }
    }
    for i in 4..8 {
        assert!(
            b.column(i).iter().all(|v| *v == 0.0),
            "column {i} past the rotors"
        );
    }
}

#[test]
fn an_unsymmetric_inertia_is_refused() {
    let allocation = Allocation::from_fn(|r, c| {
        if c < 4 {
            (r + c) as f64 * 0.1 + 0.5
        } else {
            0.0
        }
    });
    let mut inertia = Matrix3::from_diagonal(&nalgebra::Vector3::new(0.1, 0.2, 0.3));
    inertia[(0, 1)] = 0.01; // (1, 0) stays 0
    assert_eq!(
        argument(augmented_input_matrix(2.0, &inertia, &allocation, 4).unwrap_err()),
        "inertia"
    );
    // Symmetric to 1e-12 of its size passes the check.
    inertia[(1, 0)] = 0.01 + 1e-14;
    assert!(augmented_input_matrix(2.0, &inertia, &allocation, 4).is_ok());
}

#[test]
fn state_weights_must_be_finite_and_not_negative() {
    for bad in [-1.0, -1e-9, f64::NAN, f64::INFINITY] {
        let mut config = LqiConfig::default();
        config.weights.q[3] = bad;
        assert_eq!(
            argument(LqiSynthesizer::new(config).unwrap_err()),
            "weights.q",
            "q[3] = {bad}"
        );
    }
    let mut config = LqiConfig::default();
    config.weights.q[3] = 0.0;
    assert!(
        LqiSynthesizer::new(config).is_ok(),
        "a zero state weight is allowed"
    );
}

#[test]
fn k_maps_onto_the_gain_set_by_the_sec_4_table() {
    // K[r, c] = 100 r + c + 1: every entry tells its own row and column.
    let k = GainMatrix::from_fn(|r, c| (100 * r + c + 1) as f64);
    let set = gain_set_from_k(&k);
    for (r, g) in set.iter().enumerate() {
        let v = |c: usize| (100 * r + c + 1) as f64;
        // (P, I, D) = (−K[·, position], K[·, integral], −K[·, rate]).
        assert_eq!((g.z.p, g.z.i, g.z.d), (-v(0), v(8), -v(1)), "rotor {r} z");
        assert_eq!(
            (g.roll.p, g.roll.i, g.roll.d),
            (-v(2), v(9), -v(3)),
            "rotor {r} roll"
        );
        assert_eq!(
            (g.pitch.p, g.pitch.i, g.pitch.d),
            (-v(4), v(10), -v(5)),
            "rotor {r} pitch"
        );
        assert_eq!(
            (g.yaw.p, g.yaw.i, g.yaw.d),
            (-v(6), v(11), -v(7)),
            "rotor {r} yaw"
        );
    }
}

#[test]
fn clamp_gain_scales_a_column_down_to_the_wire_limit() {
    let mut set = GainSet::default();
    // Roll P column: largest |gain| 2 x 32.767 -> every rotor's roll P halved.
    let roll_p = [10.0, -2.0 * MAX_WIRE_GAIN, 4.0, 0.0];
    // Yaw D column: largest 4 x 32.767 -> quartered; pitch D inside the limit: unchanged.
    let yaw_d = [4.0 * MAX_WIRE_GAIN, 1.0, -8.0, 2.0];
    for r in 0..4 {
        set[r].roll.p = roll_p[r];
        set[r].yaw.d = yaw_d[r];
        set[r].pitch.d = MAX_WIRE_GAIN;
        set[r].roll.i = 100.0; // I gains are never clamped
    }
    let scales = clamp_gain(&mut set);
    assert!((scales.roll_p - 0.5).abs() < 1e-15);
    assert!((scales.yaw_d - 0.25).abs() < 1e-15);
    assert_eq!(scales.pitch_d, 1.0);
    for r in 0..4 {
        assert!((set[r].roll.p - roll_p[r] / 2.0).abs() < 1e-12, "rotor {r}");
        assert!((set[r].yaw.d - yaw_d[r] / 4.0).abs() < 1e-12, "rotor {r}");
        assert_eq!(set[r].pitch.d, MAX_WIRE_GAIN);
        assert_eq!(set[r].roll.i, 100.0);
    }
}

#[test]
fn max_yaw_gain_index_is_the_largest_positive_yaw_d() {
    let with = |yaw_d: &[f64]| {
        let mut set = GainSet::default();
        for (g, d) in set.iter_mut().zip(yaw_d) {
            g.yaw.d = *d;
        }
        max_yaw_gain_index(&set)
    };
    assert_eq!(with(&[0.5, 2.0, 1.0, 3.0]), Some(3));
    assert_eq!(with(&[0.5, 2.0, 1.0, -3.0]), Some(1));
    assert_eq!(with(&[-0.5, 0.0, 0.25, 0.1]), Some(2));
    assert_eq!(
        with(&[1.0, 1.0, 0.5, 0.0]),
        Some(0),
        "a tie keeps the first"
    );
    assert_eq!(with(&[-1.0, 0.0, -2.0, 0.0]), None);
    assert_eq!(with(&[]), None);
}

#[test]
fn every_error_message_names_its_cause() {
    let message = LqiError::InvalidInput { argument: "mass" }.to_string();
    assert!(message.contains("`mass`"), "{message}");
    let message = LqiError::SingularAllocation.to_string();
    assert!(message.contains("pseudo-inverse"), "{message}");
    let care = CareError::NotStabilizable;
    let message = LqiError::Care(care).to_string();
    assert!(message.contains(&care.to_string()), "{message}");
    assert!(message.starts_with("LQI synthesis"), "{message}");
}

#[test]
fn for_rotors_sets_the_count_and_keeps_the_defaults() {
    for rotors in 1..=8 {
        let config = LqiConfig::for_rotors(rotors);
        assert_eq!(config.rotors, rotors);
        assert_eq!(
            LqiConfig {
                rotors: 4,
                ..config
            },
            LqiConfig::default(),
            "{rotors} rotors: the other fields are Table V's defaults"
        );
    }
}
