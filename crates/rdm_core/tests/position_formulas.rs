//! The position controller (eqs. 30-32) against its definition written out here: the PID
//! acceleration turned into the heading frame of the target yaw by an independent rotation
//! (nalgebra's `Rotation2`), roll and pitch targets `k a / g`; and the refusal of every
//! non-finite gain and input field one at a time.

use nalgebra::{Matrix3, Rotation2, Vector2};
use rdm_core::control::position::{
    AxisPid, PositionController, PositionError, PositionGains, PositionInput, N_VECTORING,
};

fn p_only(kx: f64, ky: f64) -> PositionGains {
    let axis = |p: f64| AxisPid {
        p,
        i: 0.0,
        d: 0.0,
        integral_limit: 1.0,
    };
    PositionGains {
        x: axis(kx),
        y: axis(ky),
        k_roll: 0.8,
        k_pitch: 1.3,
        ..PositionGains::table_v()
    }
}

fn input(error: Vector2<f64>, yaw: f64) -> PositionInput {
    PositionInput {
        position: Vector2::zeros(),
        velocity: Vector2::zeros(),
        target_position: error,
        target_velocity: Vector2::zeros(),
        target_yaw: yaw,
        link_rotations: [Matrix3::identity(); N_VECTORING],
        dt: 0.025,
    }
}

#[test]
fn roll_and_pitch_targets_are_the_acceleration_in_the_heading_frame() {
    let gains = p_only(0.9, 0.6);
    for (k, &yaw) in [0.0, 0.7, -2.1, 3.0].iter().enumerate() {
        for error in [
            Vector2::new(0.3, 0.0),
            Vector2::new(0.0, -0.2),
            Vector2::new(0.25, 0.15),
        ] {
            let mut controller = PositionController::new(gains).unwrap();
            let out = controller.step(&input(error, yaw)).unwrap();
            let a = Vector2::new(gains.x.p * error.x, gains.y.p * error.y);
            assert!((out.acceleration - a).amax() < 1e-15, "case {k}");
            // the world acceleration seen from the heading frame: x forward, y left
            let heading = Rotation2::new(-yaw) * a;
            let (forward, left) = (heading.x, heading.y);
            let pitch = gains.k_pitch * forward / gains.gravity;
            let roll = gains.k_roll * (-left) / gains.gravity;
            assert!(
                (out.pitch - pitch).abs() < 1e-12,
                "yaw {yaw}: pitch {} vs {pitch}",
                out.pitch
            );
            assert!(
                (out.roll - roll).abs() < 1e-12,
                "yaw {yaw}: roll {} vs {roll}",
                out.roll
            );
            assert!(!out.saturation.any());
        }
    }
}

#[test]
fn every_non_finite_gain_is_refused() {
    let base = PositionGains::table_v();
    let mut cases: Vec<PositionGains> = Vec::new();
    for value in [f64::NAN, f64::INFINITY] {
        for field in 0..6 {
            let mut g = base;
            let axis = if field < 3 { &mut g.x } else { &mut g.y };
            match field % 3 {
                0 => axis.p = value,
                1 => axis.i = value,
                _ => axis.d = value,
            }
            cases.push(g);
        }
        let mut g = base;
        g.k_roll = value;
        cases.push(g);
        let mut g = base;
        g.k_pitch = value;
        cases.push(g);
        let mut g = base;
        g.k_roll_vectoring[0] = value;
        cases.push(g);
        let mut g = base;
        g.gravity = value;
        cases.push(g);
    }
    let mut g = base;
    g.x.integral_limit = f64::NAN;
    cases.push(g);
    let mut g = base;
    g.y.integral_limit = -1.0;
    cases.push(g);
    for (k, g) in cases.into_iter().enumerate() {
        assert_eq!(
            PositionController::new(g).err(),
            Some(PositionError::InvalidInput { argument: "gains" }),
            "case {k}"
        );
    }
    assert!(PositionController::new(base).is_ok());
}

#[test]
fn every_non_finite_input_field_is_refused_by_name() {
    let mut controller = PositionController::new(PositionGains::table_v()).unwrap();
    let good = input(Vector2::new(0.1, 0.1), 0.2);
    let mut cases: Vec<(PositionInput, &str)> = Vec::new();
    let mut i = good;
    i.position.x = f64::NAN;
    cases.push((i, "position"));
    let mut i = good;
    i.velocity.y = f64::INFINITY;
    cases.push((i, "velocity"));
    let mut i = good;
    i.target_position.y = f64::NAN;
    cases.push((i, "target_position"));
    let mut i = good;
    i.target_velocity.x = f64::NEG_INFINITY;
    cases.push((i, "target_velocity"));
    let mut i = good;
    i.target_yaw = f64::NAN;
    cases.push((i, "target_yaw"));
    let mut i = good;
    i.dt = 0.0;
    cases.push((i, "dt"));
    let mut i = good;
    i.link_rotations[0] *= 2.0;
    cases.push((i, "link_rotations"));
    for (i, argument) in cases {
        assert_eq!(
            controller.step(&i).err(),
            Some(PositionError::InvalidInput { argument }),
            "{argument}"
        );
    }
    // a refused step leaves the integrator untouched
    assert_eq!(controller.integral(), Vector2::zeros());
    assert!(controller.step(&good).is_ok());
}

#[test]
fn vectoring_angles_turn_the_z_axis_onto_the_direction() {
    use nalgebra::{Rotation3, Vector3};
    use rdm_core::control::position::vectoring_angles;
    let directions = [
        Vector3::new(0.3, -0.2, 0.9),
        Vector3::new(-0.5, 0.4, 0.7),
        Vector3::new(0.1, 0.6, 0.3),
        Vector3::new(0.0, 0.0, 1.0),
        Vector3::new(0.7, 0.0, 0.7),
    ];
    for n in directions {
        let n = n.normalize();
        let (alpha, beta) = vectoring_angles(&n);
        // eqs. (33)-(34): R_x(alpha) R_y(beta) e_z = n
        let turned = Rotation3::from_axis_angle(&Vector3::x_axis(), alpha)
            * Rotation3::from_axis_angle(&Vector3::y_axis(), beta)
            * Vector3::z();
        assert!(
            (turned - n).amax() < 1e-12,
            "{n:?}: {alpha} {beta} -> {turned:?}"
        );
    }
}

#[test]
fn a_gain_switch_carries_the_integral_action_and_a_zero_gain_starts_at_zero() {
    let mut old_gains = PositionGains::table_v();
    old_gains.x.i = 1.5;
    old_gains.y.i = 0.4;
    let mut old = PositionController::new(old_gains).unwrap();
    for _ in 0..20 {
        old.step(&input(Vector2::new(0.2, -0.3), 0.0)).unwrap();
    }
    let action = Vector2::new(1.5 * old.integral().x, 0.4 * old.integral().y);
    assert!(action.x.abs() > 1e-3 && action.y.abs() > 1e-3);
    let mut new_gains = old_gains;
    new_gains.x.i = 3.0;
    new_gains.y.i = 0.0;
    let mut new = PositionController::new(new_gains).unwrap();
    new.take_integral_action(&old);
    assert!((3.0 * new.integral().x - action.x).abs() < 1e-12);
    assert_eq!(new.integral().y, 0.0);
}

#[test]
fn a_target_exactly_at_the_tilt_bound_is_not_a_cut() {
    let mut gains = p_only(0.0, 0.0);
    gains.k_pitch = 1.0;
    gains.x.p = 1.0;
    let edge = gains.gravity * gains.max_tilt; // pitch = k_pitch * a / g = max_tilt
    let mut controller = PositionController::new(gains).unwrap();
    let out = controller
        .step(&input(Vector2::new(edge, 0.0), 0.0))
        .unwrap();
    assert!((out.pitch - gains.max_tilt).abs() < 1e-15);
    assert!(!out.saturation.attitude);
}
