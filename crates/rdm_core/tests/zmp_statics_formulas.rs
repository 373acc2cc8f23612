//! The aerial support polygon's degenerate cases (eq. 1) and the net wrench that
//! `static_torques` (eq. 61) returns, each against a value derived by hand or from the
//! model's mass properties (`ws.mass`, `ws.cog`), never from the statics code itself.

use nalgebra::{Isometry3, Vector2, Vector3};
use rdm_core::model::{
    allocation_bar, support_margin, Matrix4xN, ModelWorkspace, RobotDescription, StaticLoads,
};

const RDM_URDF: &str = include_str!("../../../python/rdm/data/robots/rdm/rdm.urdf");
const RDM_TOML: &str = include_str!("../../../python/rdm/data/robots/rdm/rdm.toml");
const G: f64 = 9.80665;

fn rdm() -> RobotDescription {
    RobotDescription::from_strs(RDM_URDF, RDM_TOML, "rdm.urdf", "rdm.toml")
        .expect("shipped RDM loads")
}

#[test]
fn a_sliver_triangle_is_degenerate_and_measured_to_its_long_edge() {
    // Area 0.5 * 1 * 1e-11 = 5e-12 m^2, below the 1e-10 m^2 floor although the hull keeps
    // three vertices: no interior, margin = minus the distance to the segment (0,0)-(1,0).
    let mut hull = Vec::with_capacity(16);
    let mut sliver = [
        Vector2::new(0.0, 0.0),
        Vector2::new(1.0, 0.0),
        Vector2::new(0.5, 1e-11),
    ];
    let (m, degenerate) = support_margin(&mut sliver, &Vector2::new(0.5, 1.0), &mut hull);
    assert!(degenerate, "a 5e-12 m^2 triangle has no interior");
    assert!((m + 1.0).abs() < 1e-9, "margin {m}");
    // Its centre is not inside either: never a positive margin for a degenerate polygon.
    let (m, degenerate) = support_margin(&mut sliver, &Vector2::new(0.5, 3e-12), &mut hull);
    assert!(degenerate && m <= 0.0, "margin {m}");
}

#[test]
fn rotors_on_a_line_along_y_span_a_segment_along_y() {
    // Collinear along y: the segment runs (0,0)-(0,2); from (1,1) it is 1 m away, from
    // (0,3) 1 m beyond its end, from (0,1.5) on it.
    let mut hull = Vec::with_capacity(16);
    let mut line = [
        Vector2::new(0.0, 0.0),
        Vector2::new(0.0, 2.0),
        Vector2::new(0.0, 1.0),
    ];
    for (p, expected) in [
        (Vector2::new(1.0, 1.0), -1.0),
        (Vector2::new(0.0, 3.0), -1.0),
        (Vector2::new(0.0, -0.5), -0.5),
        (Vector2::new(0.0, 1.5), 0.0),
    ] {
        let (m, degenerate) = support_margin(&mut line, &p, &mut hull);
        assert!(degenerate);
        assert!((m - expected).abs() < 1e-12, "{p:?}: {m} vs {expected}");
    }
    // The same along a diagonal of length 2 sqrt 2: (3,3) is sqrt 2 past (2,2).
    let mut diagonal = [
        Vector2::new(2.0, 2.0),
        Vector2::new(0.0, 0.0),
        Vector2::new(1.0, 1.0),
    ];
    let (m, degenerate) = support_margin(&mut diagonal, &Vector2::new(3.0, 3.0), &mut hull);
    assert!(degenerate && (m + 2f64.sqrt()).abs() < 1e-12, "margin {m}");
    let (m, _) = support_margin(&mut diagonal, &Vector2::new(0.0, 2.0), &mut hull);
    assert!((m + 2f64.sqrt()).abs() < 1e-12, "margin {m}");
}

/// The bent, level configuration of the eq. (73) model test: every thrust vertical.
const LEVEL_Q: [f64; 10] = [0.0, 0.0, 0.4, 0.0, -0.7, 0.3, 0.0, 0.0, 0.0, 0.0];

fn cross_weight(cog: &Vector3<f64>, force: &Vector3<f64>) -> Vector3<f64> {
    // (c - 0) x f written out component by component.
    Vector3::new(
        cog.y * force.z - cog.z * force.y,
        cog.z * force.x - cog.x * force.z,
        cog.x * force.y - cog.y * force.x,
    )
}

#[test]
fn static_residual_is_the_weight_about_the_base_origin() {
    // Gravity alone: the base must supply -(net wrench); the net wrench is the weight
    // m g at the CoG, i.e. force (0, 0, -m g) and moment c x (0, 0, -m g) about the origin.
    let robot = rdm();
    let mut ws = ModelWorkspace::new(&robot);
    let base = Isometry3::translation(0.2, -0.1, 0.3);
    robot.evaluate(&LEVEL_Q, &base, &mut ws).unwrap();
    let zeros = vec![0.0; robot.n_rotors()];
    let g = [0.0, 0.0, -G];
    let loads = StaticLoads {
        thrusts: &zeros,
        foot_wrench: &[0.0; 6],
        end_effector_wrench: &[0.0; 6],
        gravity: &g,
    };
    let mut tau = vec![0.0; robot.n_q()];
    let residual = robot.static_torques(&ws, &loads, &mut tau).unwrap();
    let weight = Vector3::new(0.0, 0.0, -robot.total_mass() * G);
    let moment = cross_weight(&(ws.cog - base.translation.vector), &weight);
    for k in 0..3 {
        assert!(
            (residual[k] - weight[k]).abs() < 1e-9,
            "force {k}: {residual}"
        );
        assert!(
            (residual[3 + k] - moment[k]).abs() < 1e-9,
            "moment {k}: {residual}"
        );
    }
    assert!(
        moment.norm() > 0.1,
        "the CoG is off the base origin: {moment}"
    );

    // A foot wrench alone at the foot origin f: force f, moment (p_foot - base) x f + m.
    let foot = [1.0, -2.0, 3.0, 0.1, 0.2, -0.3];
    let loads = StaticLoads {
        thrusts: &zeros,
        foot_wrench: &foot,
        end_effector_wrench: &[0.0; 6],
        gravity: &[0.0; 3],
    };
    let residual = robot.static_torques(&ws, &loads, &mut tau).unwrap();
    let foot_frame = robot.frame("foot").unwrap();
    let p = robot
        .frame_pose(&ws, foot_frame)
        .unwrap()
        .translation
        .vector
        - base.translation.vector;
    let f = Vector3::new(foot[0], foot[1], foot[2]);
    let m = cross_weight(&p, &f) + Vector3::new(foot[3], foot[4], foot[5]);
    for k in 0..3 {
        assert!((residual[k] - f[k]).abs() < 1e-12, "force {k}: {residual}");
        assert!(
            (residual[3 + k] - m[k]).abs() < 1e-12,
            "moment {k}: {residual}"
        );
    }
}

#[test]
fn hover_thrusts_leave_no_static_residual() {
    // Thrusts from Q-bar's pseudo-inverse that lift m g with no moment about the CoG balance
    // the weight: the net wrench on the robot is zero, so the base supplies nothing.
    let robot = rdm();
    let mut ws = ModelWorkspace::new(&robot);
    robot
        .evaluate(&LEVEL_Q, &Isometry3::identity(), &mut ws)
        .unwrap();
    let mut q_bar = Matrix4xN::zeros(robot.n_rotors());
    assert!(allocation_bar(&ws, &mut q_bar));
    let target = nalgebra::Vector4::new(robot.total_mass() * G, 0.0, 0.0, 0.0);
    let lambda = q_bar.pseudo_inverse(1e-12).unwrap() * target;
    assert!(ws.rotor_direction.iter().all(|u| (u.z - 1.0).abs() < 1e-12));
    let g = [0.0, 0.0, -G];
    let loads = StaticLoads {
        thrusts: lambda.as_slice(),
        foot_wrench: &[0.0; 6],
        end_effector_wrench: &[0.0; 6],
        gravity: &g,
    };
    let mut tau = vec![0.0; robot.n_q()];
    let residual = robot.static_torques(&ws, &loads, &mut tau).unwrap();
    assert!(residual.norm() < 1e-9, "residual {residual}");
}
