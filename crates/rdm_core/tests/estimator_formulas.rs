//! The estimator's closed forms against their definitions written out here: the quaternion of
//! a rotation matrix (Shepperd's method, every branch) against the matrix of a known unit
//! quaternion, and the magnetic complementary filter `m <- (m K + m_new) / (K + 1)` against the
//! heading vector before and after one step (firmware configuration, gyro at rest).

use nalgebra::Matrix3;
use rdm_core::estimate::{quaternion_xyzw, AttitudeEstimator, EstimatorConfig, ImuSample};

/// The rotation matrix of the unit quaternion (x, y, z, w), the textbook form.
fn matrix_of(q: [f64; 4]) -> Matrix3<f64> {
    let [x, y, z, w] = q;
    Matrix3::new(
        1.0 - 2.0 * (y * y + z * z),
        2.0 * (x * y - z * w),
        2.0 * (x * z + y * w),
        2.0 * (x * y + z * w),
        1.0 - 2.0 * (x * x + z * z),
        2.0 * (y * z - x * w),
        2.0 * (x * z - y * w),
        2.0 * (y * z + x * w),
        1.0 - 2.0 * (x * x + y * y),
    )
}

fn unit(q: [f64; 4]) -> [f64; 4] {
    let n = q.iter().map(|v| v * v).sum::<f64>().sqrt();
    let s = if q[3] < 0.0 { -1.0 / n } else { 1.0 / n };
    q.map(|v| v * s)
}

#[test]
fn quaternion_of_a_matrix_is_the_quaternion_it_was_built_from_in_every_branch() {
    // A small deterministic generator (no dependency): each case perturbs a dominant
    // component, so each of Shepperd's four branches (w, x, y, z largest) is taken.
    let mut state = 0x2545_f491_4f6c_dd1d_u64;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    };
    let mut branches = [0usize; 4];
    for case in 0..400 {
        let dominant = case % 4;
        let mut q = [next(), next(), next(), next()];
        // index 3 is w; the others x, y, z
        let slot = [3, 0, 1, 2][dominant];
        q[slot] = 2.0 + next();
        let q = unit(q);
        let r = matrix_of(q);
        let trace = r[(0, 0)] + r[(1, 1)] + r[(2, 2)];
        let largest_diag = (0..3)
            .max_by(|&a, &b| r[(a, a)].total_cmp(&r[(b, b)]))
            .unwrap();
        branches[if trace > 0.0 { 0 } else { 1 + largest_diag }] += 1;
        let got = quaternion_xyzw(&r);
        for k in 0..4 {
            assert!(
                (got[k] - q[k]).abs() < 1e-12,
                "case {case}: component {k}: {got:?} vs {q:?}"
            );
        }
    }
    assert!(
        branches.iter().all(|&n| n > 0),
        "branches taken: {branches:?}"
    );
}

#[test]
fn a_new_magnetometer_sample_pulls_the_heading_by_one_over_k_plus_one() {
    let config = EstimatorConfig::firmware(200.0);
    let k = config.mag_cmpf_factor;
    let mut estimator = AttitudeEstimator::new(config).unwrap();
    let at_rest = |mag: [f64; 3]| ImuSample {
        gyro: [0.0; 3],
        acc: [0.0, 0.0, 9.80665],
        mag,
    };
    let mags = [
        [20.0, 5.0, -40.0],
        [21.0, 4.5, -39.0],
        [19.5, 6.0, -41.0],
        [22.0, 3.0, -38.5],
    ];
    for _ in 0..10 {
        estimator.step(&at_rest(mags[0]));
    }
    for m in &mags[1..] {
        let before = estimator.heading_vector();
        estimator.step(&at_rest(*m));
        let after = estimator.heading_vector();
        for i in 0..3 {
            let expected = (before[i] * k + m[i]) / (k + 1.0);
            assert!(
                (after[i] - expected).abs() < 1e-12 * expected.abs().max(1.0),
                "axis {i}: {} vs {expected}",
                after[i]
            );
        }
        // an unchanged sample leaves the heading where it is (the filter acts on change)
        estimator.step(&at_rest(*m));
        assert_eq!(estimator.heading_vector(), after);
    }
}

#[test]
fn rotation_from_euler_is_rz_ry_rx() {
    use nalgebra::Rotation3;
    for &(roll, pitch, yaw) in &[
        (0.3, -0.2, 1.1),
        (-1.2, 0.7, -2.5),
        (2.9, -1.4, 0.4),
        (0.0, 0.0, 3.0),
    ] {
        let expected = Rotation3::from_euler_angles(roll, pitch, yaw).into_inner();
        let got = rdm_core::estimate::rotation_from_euler(roll, pitch, yaw);
        assert!((got - expected).amax() < 1e-14, "{roll} {pitch} {yaw}");
        let back = rdm_core::estimate::euler_zyx(&got);
        for (a, b) in back.iter().zip([roll, pitch, yaw]) {
            assert!((a - b).abs() < 1e-12);
        }
    }
}

#[test]
fn a_level_still_estimate_is_ok_and_not_degraded_with_or_without_guards() {
    for config in [
        EstimatorConfig::new(200.0),
        EstimatorConfig::firmware(200.0),
    ] {
        let samples = (config.gyro_calib_duration_s * config.rate_hz) as usize + 20;
        let mut estimator = AttitudeEstimator::new(config).unwrap();
        let mut last = None;
        for _ in 0..samples {
            last = Some(estimator.step(&ImuSample {
                gyro: [0.0; 3],
                acc: [0.0, 0.0, 9.80665],
                mag: [20.0, 0.0, -40.0],
            }));
        }
        assert_eq!(last, Some(rdm_core::estimate::EstimateStatus::Ok));
        assert!(!estimator.degraded());
    }
}

#[test]
fn half_turns_about_each_axis_take_the_branch_that_can_divide() {
    // 180 deg about x, y, z: w = 0 and only the axis's own branch has a non-zero divisor.
    let cases = [
        (
            Matrix3::new(1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, -1.0),
            [1.0, 0.0, 0.0, 0.0],
        ),
        (
            Matrix3::new(-1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, -1.0),
            [0.0, 1.0, 0.0, 0.0],
        ),
        (
            Matrix3::new(-1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, 1.0),
            [0.0, 0.0, 1.0, 0.0],
        ),
    ];
    for (r, q) in cases {
        assert_eq!(matrix_of(q), r);
        assert_eq!(quaternion_xyzw(&r), q, "{r:?}");
    }
}
