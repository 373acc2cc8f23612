//! Unit tests of the model's pure math against independent computations (finite
//! differences, virtual work, hand-made polygons). MuJoCo comparisons live in pytest.

use nalgebra::{Isometry3, Vector2, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::*;

const RDM_URDF: &str = include_str!("../../../../python/rdm/data/robots/rdm/rdm.urdf");
const RDM_TOML: &str = include_str!("../../../../python/rdm/data/robots/rdm/rdm.toml");

fn rdm() -> RobotDescription {
    RobotDescription::from_strs(RDM_URDF, RDM_TOML, "rdm.urdf", "rdm.toml")
        .expect("shipped RDM loads")
}

fn random_zeta(rng: &mut ChaCha8Rng, n_q: usize) -> Vec<f64> {
    (0..6 + n_q)
        .map(|k| {
            if k < 3 {
                rng.random_range(-1.0..1.0)
            } else {
                rng.random_range(-1.4..1.4)
            }
        })
        .collect()
}

fn eval_zeta(robot: &RobotDescription, ws: &mut ModelWorkspace, zeta: &[f64]) {
    let base = base_pose_from_zeta(
        &Vector3::new(zeta[0], zeta[1], zeta[2]),
        &Vector3::new(zeta[3], zeta[4], zeta[5]),
    );
    robot.evaluate(&zeta[6..], &base, ws).expect("evaluate");
}

#[test]
fn shipped_rdm_matches_table_iv_mass() {
    let robot = rdm();
    assert_eq!(robot.n_q(), 10);
    assert_eq!(robot.n_rotors(), 4);
    assert!(
        (robot.total_mass() - 3.70).abs() < 1e-9,
        "mass {}",
        robot.total_mass()
    );
    assert_eq!(robot.joint_order[6], "alpha1");
}

#[test]
fn frame_jacobians_match_finite_differences() {
    let robot = rdm();
    let mut ws = ModelWorkspace::new(&robot);
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let n = 6 + robot.n_q();
    let mut jac = Matrix6xN::zeros(n);
    let frames = [
        "end_effector",
        "foot",
        "cog",
        "rotor1",
        "rotor4",
        "middle_link",
    ];
    let h = 1e-6;
    for _ in 0..20 {
        let zeta = random_zeta(&mut rng, robot.n_q());
        for name in frames {
            let frame = robot.frame(name).unwrap();
            eval_zeta(&robot, &mut ws, &zeta);
            robot.frame_jacobian(&ws, frame, &mut jac).unwrap();
            for k in 0..n {
                let mut plus = zeta.clone();
                plus[k] += h;
                let mut minus = zeta.clone();
                minus[k] -= h;
                eval_zeta(&robot, &mut ws, &plus);
                let pp = robot.frame_pose(&ws, frame).unwrap();
                eval_zeta(&robot, &mut ws, &minus);
                let pm = robot.frame_pose(&ws, frame).unwrap();
                let dp = (pp.translation.vector - pm.translation.vector) / (2.0 * h);
                let dr = (pp.rotation * pm.rotation.inverse()).scaled_axis() / (2.0 * h);
                for r in 0..3 {
                    assert!(
                        (jac[(r, k)] - dp[r]).abs() < 1e-6,
                        "{name} lin ({r},{k}): {} vs {}",
                        jac[(r, k)],
                        dp[r]
                    );
                    assert!(
                        (jac[(3 + r, k)] - dr[r]).abs() < 1e-6,
                        "{name} ang ({r},{k}): {} vs {}",
                        jac[(3 + r, k)],
                        dr[r]
                    );
                }
            }
        }
    }
}

#[test]
fn static_gravity_torques_equal_potential_energy_gradient() {
    // Virtual work: with only gravity, tau = dV/dq where V = -sum m_l g . c_l (foot fixed).
    let robot = rdm();
    let mut ws = ModelWorkspace::new(&robot);
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let g = [0.0, 0.0, -9.80665];
    let zeros = vec![0.0; robot.n_rotors()];
    let loads = StaticLoads {
        thrusts: &zeros,
        foot_wrench: &[0.0; 6],
        end_effector_wrench: &[0.0; 6],
        gravity: &g,
    };
    let mut tau = vec![0.0; robot.n_q()];
    let base = Isometry3::identity();
    let potential = |ws: &ModelWorkspace| ws.mass * 9.80665 * ws.cog.z;
    for _ in 0..10 {
        let q: Vec<f64> = (0..robot.n_q())
            .map(|_| rng.random_range(-1.5..1.5))
            .collect();
        robot.evaluate(&q, &base, &mut ws).unwrap();
        robot.static_torques(&ws, &loads, &mut tau).unwrap();
        for k in 0..robot.n_q() {
            let h = 1e-6;
            let mut qp = q.clone();
            qp[k] += h;
            robot.evaluate(&qp, &base, &mut ws).unwrap();
            let vp = potential(&ws);
            qp[k] -= 2.0 * h;
            robot.evaluate(&qp, &base, &mut ws).unwrap();
            let vm = potential(&ws);
            let dv = (vp - vm) / (2.0 * h);
            assert!(
                (tau[k] - dv).abs() < 1e-6,
                "q{k}: tau {} vs dV/dq {}",
                tau[k],
                dv
            );
        }
    }
}

#[test]
#[allow(clippy::needless_range_loop)] // index form mirrors the equations
fn rotor_torques_equal_virtual_work_of_thrust() {
    // A thrust lambda_i u_i and drag torque do virtual work; for fixed world force F and
    // moment M on a body, tau_j = -(F . dp/dq_j + M . dtheta/dq_j).
    let robot = rdm();
    let mut ws = ModelWorkspace::new(&robot);
    let q = [0.3, -0.4, 0.5, 0.2, -0.6, 0.1, 0.7, -0.2, 0.4, 0.9];
    let base = Isometry3::identity();
    robot.evaluate(&q, &base, &mut ws).unwrap();
    let thrusts = [3.0, 5.0, 7.0, 11.0];
    let loads = StaticLoads {
        thrusts: &thrusts,
        foot_wrench: &[0.0; 6],
        end_effector_wrench: &[1.0, -2.0, 3.0, 0.1, 0.2, -0.3],
        gravity: &[0.0; 3],
    };
    let mut tau = vec![0.0; 10];
    robot.static_torques(&ws, &loads, &mut tau).unwrap();
    let mut expected = [0.0; 10];
    let mut jac = Matrix6xN::zeros(16);
    for i in 0..4 {
        robot
            .frame_jacobian(&ws, Frame::Rotor(i), &mut jac)
            .unwrap();
        let f = thrusts[i] * ws.rotor_direction[i];
        let m = -robot.rotors[i].drag_to_thrust * robot.rotors[i].spin * f;
        for k in 0..10 {
            let col = jac.column(6 + k);
            expected[k] -= f.dot(&col.fixed_rows::<3>(0)) + m.dot(&col.fixed_rows::<3>(3));
        }
    }
    robot
        .frame_jacobian(&ws, robot.frame("end_effector").unwrap(), &mut jac)
        .unwrap();
    let f = Vector3::new(1.0, -2.0, 3.0);
    let m = Vector3::new(0.1, 0.2, -0.3);
    for k in 0..10 {
        let col = jac.column(6 + k);
        expected[k] -= f.dot(&col.fixed_rows::<3>(0)) + m.dot(&col.fixed_rows::<3>(3));
    }
    for k in 0..10 {
        assert!(
            (tau[k] - expected[k]).abs() < 1e-12,
            "q{k}: {} vs {}",
            tau[k],
            expected[k]
        );
    }
}

#[test]
fn support_margin_of_hand_made_polygons() {
    let mut hull = Vec::with_capacity(16);
    let mut square = [
        Vector2::new(0.0, 0.0),
        Vector2::new(1.0, 0.0),
        Vector2::new(1.0, 1.0),
        Vector2::new(0.0, 1.0),
        Vector2::new(0.5, 0.5),
    ];
    let (m, d) = support_margin(&mut square, &Vector2::new(0.5, 0.25), &mut hull);
    assert!(!d && (m - 0.25).abs() < 1e-12);
    let (m, d) = support_margin(&mut square, &Vector2::new(2.0, 2.0), &mut hull);
    assert!(!d && (m + 2f64.sqrt()).abs() < 1e-12);
    let mut line = [
        Vector2::new(0.0, 0.0),
        Vector2::new(2.0, 0.0),
        Vector2::new(1.0, 0.0),
    ];
    let (m, d) = support_margin(&mut line, &Vector2::new(1.0, 0.0), &mut hull);
    assert!(d && m == 0.0);
    let (m, d) = support_margin(&mut line, &Vector2::new(3.0, 0.0), &mut hull);
    assert!(d && (m + 1.0).abs() < 1e-12);
    let mut point = [Vector2::new(1.0, 1.0); 4];
    let (m, d) = support_margin(&mut point, &Vector2::new(1.0, 4.0), &mut hull);
    assert!(d && (m + 3.0).abs() < 1e-12);
}

#[test]
fn eq73_with_balancing_thrusts_equals_cog_projection() {
    // Vertical thrusts that cancel roll/pitch moments about the CoG put eq. (73) on the CoG.
    let robot = rdm();
    let mut ws = ModelWorkspace::new(&robot);
    // Bent arm with every thrust vertical: q2 = -q4 keeps the middle-to-end chain level,
    // yaw joints move the rotors sideways, units untilted.
    let q = [0.0, 0.0, 0.4, 0.0, -0.7, 0.3, 0.0, 0.0, 0.0, 0.0];
    robot.evaluate(&q, &Isometry3::identity(), &mut ws).unwrap();
    let mut q_bar = Matrix4xN::zeros(4);
    assert!(allocation_bar(&ws, &mut q_bar));
    let target = nalgebra::Vector4::new(ws.mass * 9.8, 0.0, 0.0, 0.0);
    let lambda = q_bar.clone().pseudo_inverse(1e-12).unwrap() * target;
    let from_thrusts = robot
        .aerial_zmp_from_thrusts(&mut ws, lambda.as_slice())
        .unwrap()
        .unwrap();
    let steady = robot.aerial_zmp(&mut ws).unwrap();
    assert!(ws.rotor_direction.iter().all(|u| (u.z - 1.0).abs() < 1e-12));
    assert!((from_thrusts.point - steady.point).norm() < 1e-9);
}

#[test]
fn bad_inputs_return_errors() {
    let robot = rdm();
    let mut ws = ModelWorkspace::new(&robot);
    let base = Isometry3::identity();
    assert!(matches!(
        robot.evaluate(&[0.0; 9], &base, &mut ws),
        Err(ModelError::WrongLength { what: "q", .. })
    ));
    let mut q = [0.0; 10];
    q[3] = f64::NAN;
    assert_eq!(
        robot.evaluate(&q, &base, &mut ws),
        Err(ModelError::NonFinite {
            what: "q",
            index: 3
        })
    );
    assert_eq!(robot.stability(&ws), Err(ModelError::NotEvaluated));
    assert!(matches!(
        robot.frame("nope"),
        Err(ModelError::UnknownFrame(_))
    ));
    let mut bad_base = base;
    bad_base.translation.vector.x = f64::INFINITY;
    assert!(robot.evaluate(&[0.0; 10], &bad_base, &mut ws).is_err());
}

#[test]
fn stability_gradient_is_zero_for_base_and_matches_rho_changes() {
    let robot = rdm();
    let mut ws = ModelWorkspace::new(&robot);
    let q = [0.5, -0.5, 0.2, 0.8, 0.6, 0.0, 0.1, 0.2, 0.3, 0.4];
    let base = Isometry3::rotation(Vector3::new(0.1, 0.2, 0.3));
    let mut grad = vec![1.0; 16];
    robot
        .stability_gradient(&q, &base, &mut ws, &mut grad)
        .unwrap();
    assert!(grad[..6].iter().all(|&g| g == 0.0));
    // A small step along the gradient raises rho by about |grad|^2 * step.
    let rho0 = robot.stability(&ws).unwrap();
    let step = 1e-4;
    let q2: Vec<f64> = q
        .iter()
        .zip(&grad[6..])
        .map(|(a, g)| a + step * g)
        .collect();
    robot.evaluate(&q2, &base, &mut ws).unwrap();
    let rho1 = robot.stability(&ws).unwrap();
    let predicted = step * grad[6..].iter().map(|g| g * g).sum::<f64>();
    assert!(((rho1 - rho0) - predicted).abs() < 0.05 * predicted.abs() + 1e-12);
}

#[test]
fn description_errors_name_the_field() {
    let bad_mass = RDM_URDF.replacen("<mass value=\"0.35\"/>", "<mass value=\"-0.35\"/>", 1);
    let e = RobotDescription::from_strs(&bad_mass, RDM_TOML, "x.urdf", "x.toml").unwrap_err();
    assert_eq!(e.kind, DescriptionErrorKind::NegativeMass);
    assert!(
        e.to_string().contains("x.urdf") && e.to_string().contains("link 'foot'"),
        "{e}"
    );
    let bad_parent = RDM_TOML.replacen("parent = \"foot_unit_pitch\"", "parent = \"nowhere\"", 1);
    let e = RobotDescription::from_strs(RDM_URDF, &bad_parent, "x.urdf", "x.toml").unwrap_err();
    assert!(
        e.to_string().contains("rotors[0]") && e.to_string().contains("nowhere"),
        "{e}"
    );
    let e = RobotDescription::from_strs("<robot><link", RDM_TOML, "x.urdf", "x.toml").unwrap_err();
    assert_eq!(e.kind, DescriptionErrorKind::Syntax);
}
