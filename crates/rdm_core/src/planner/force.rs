//! Feasible end-effector force of eq. (3) at one perched configuration: for each axis j
//! and sign, max f such that F_ee = ±f e_j can be held with thrust changes dλ while
//! every joint torque stays within its stall torque (eq. 61), every thrust within
//! [lambda_min, lambda-bar+] (eqs. 45, 64) and the foot stays perched: normal force > 0,
//! friction pyramid (eqs. 39-40), yaw friction (eq. 41) and ZMP inside the plate (eq. 42).
//! A small LP per axis and sign, solved with the dense QP (P = tiny regulariser).

use nalgebra::{SVector, Vector3, Vector6};

use super::thrust::{static_thrust, world_allocation};
use crate::model::{ModelWorkspace, RobotDescription, StaticLoads};
use crate::qp::{DenseQp, QpSettings};

/// Largest force the LP may return [N] (keeps the LP bounded).
pub const FORCE_CAP: f64 = 200.0;
/// Minimum normal force kept on the ceiling [N] (epsilon_z of eq. 39).
pub const MIN_NORMAL_FORCE: f64 = 0.5;

/// Feasible force per axis (max over both signs) and eq. (3)'s maximum.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FeasibleForce {
    pub per_axis: [f64; 3],
    pub feasible: f64,
}

const NV: usize = 5; // f, dλ1..4

/// Feasible force at the configuration evaluated in `ws` (levelled units, perched
/// with preload `perch_force`). Returns zeros where even f = 0 is infeasible.
pub fn feasible_force(
    robot: &RobotDescription,
    ws: &ModelWorkspace,
    gravity: f64,
    perch_force: f64,
) -> Option<FeasibleForce> {
    let n_q = robot.n_q();
    if robot.n_rotors() != 4 {
        return None;
    }
    let base = static_thrust(robot, ws, gravity, Some(perch_force), &[0.0; 3])?;
    let foot = ws.link_pose[robot.foot_link].translation.vector;
    let q_foot_inv = world_allocation(robot, ws, &foot).try_inverse()?;
    let zero6 = [0.0; 6];
    let g = [0.0, 0.0, -gravity];
    // Torques and the wrench left for the ceiling (about the foot) are affine in x.
    let torque_and_wrench = |thr: &[f64; 4], ee: &[f64; 6], grav: &[f64; 3]| {
        let mut tau = vec![0.0; n_q];
        let r = robot
            .static_torques(
                ws,
                &StaticLoads {
                    thrusts: thr,
                    foot_wrench: &zero6,
                    end_effector_wrench: ee,
                    gravity: grav,
                },
                &mut tau,
            )
            .ok()?;
        let lever = foot - ws.base.translation.vector;
        let f: Vector3<f64> = r.fixed_rows::<3>(0).into_owned();
        let m: Vector3<f64> = r.fixed_rows::<3>(3).into_owned() - lever.cross(&f);
        // Foot wrench = minus the residual (about the foot).
        Some((tau, Vector6::new(-f.x, -f.y, -f.z, -m.x, -m.y, -m.z)))
    };
    let t0 = [
        base.thrust[0],
        base.thrust[1],
        base.thrust[2],
        base.thrust[3],
    ];
    let (tau0, w0) = torque_and_wrench(&t0, &zero6, &g)?;
    let mut thrust_cols = Vec::with_capacity(4);
    for i in 0..4 {
        let mut e = [0.0; 4];
        e[i] = 1.0;
        thrust_cols.push(torque_and_wrench(&e, &zero6, &[0.0; 3])?);
    }
    let (hx, hy) = (0.5 * robot.plate_size[0], 0.5 * robot.plate_size[1]);
    let (mu, mu_z) = (robot.friction_xy, robot.friction_z);
    // Rows: torque ±(2 n_q), thrust upper and lower (8), normal force (1), friction x/y,
    // yaw friction and ZMP x/y as ± pairs (10), force in [0, FORCE_CAP] (2).
    let n_rows = 2 * n_q + 8 + 1 + 10 + 2;
    let mut qp = DenseQp::new(NV, 0, n_rows, QpSettings::default()).ok()?;
    let mut per_axis = [0.0f64; 3];
    for (j, best) in per_axis.iter_mut().enumerate() {
        for sign in [1.0, -1.0] {
            let mut ee = [0.0; 6];
            ee[j] = sign;
            let (tau_f, w_f) = torque_and_wrench(&[0.0; 4], &ee, &[0.0; 3])?;
            let mut g_rows: Vec<SVector<f64, NV>> = Vec::new();
            let mut h_rows: Vec<f64> = Vec::new();
            let mut push = |row: SVector<f64, NV>, h: f64| {
                g_rows.push(row);
                h_rows.push(h);
            };
            for i in 0..n_q {
                let mut a = SVector::<f64, NV>::zeros();
                a[0] = tau_f[i];
                for k in 0..4 {
                    a[1 + k] = thrust_cols[k].0[i];
                }
                let s = robot.stall_torque[i];
                push(a, s - tau0[i]);
                push(-a, s + tau0[i]);
            }
            for k in 0..4 {
                let rotor = &robot.rotors[k];
                let mut a = SVector::<f64, NV>::zeros();
                a[1 + k] = 1.0;
                // eq. (64): the tangential force needs |F_xy|/mu more perching force.
                if j < 2 {
                    a[0] = q_foot_inv[(k, 0)] / mu.max(1e-6);
                }
                push(a, rotor.thrust_max - t0[k]);
                let mut low = SVector::<f64, NV>::zeros();
                low[1 + k] = -1.0;
                push(low, t0[k] - rotor.thrust_min);
            }
            // Foot wrench w = w0 + w_f f + Σ w_k dλ_k; the ceiling pushes down: N = -w_z.
            let lin = |c: usize| {
                let mut a = SVector::<f64, NV>::zeros();
                a[0] = w_f[c];
                for k in 0..4 {
                    a[1 + k] = thrust_cols[k].1[c];
                }
                a
            };
            let n_row = -lin(2);
            let n0 = -w0[2];
            // N >= eps  ->  -N <= -eps
            push(-n_row, n0 - MIN_NORMAL_FORCE);
            for (c, lim) in [(0, mu), (1, mu), (5, mu_z), (3, hy), (4, hx)] {
                // |w_c| <= lim N  ->  ±w_c - lim N <= 0
                let a = lin(c);
                push(a - n_row * lim, lim * n0 - w0[c]);
                push(-a - n_row * lim, lim * n0 + w0[c]);
            }
            let mut a = SVector::<f64, NV>::zeros();
            a[0] = 1.0;
            push(a, FORCE_CAP);
            a[0] = -1.0;
            push(a, 0.0);
            if g_rows.len() != n_rows {
                return None;
            }
            let mut gm = vec![0.0; n_rows * NV];
            for (r, row) in g_rows.iter().enumerate() {
                gm[r * NV..(r + 1) * NV].copy_from_slice(row.as_slice());
            }
            let mut p = [0.0; NV * NV];
            for k in 0..NV {
                p[k * NV + k] = 1e-6;
            }
            let mut q = [0.0; NV];
            q[0] = -1.0;
            let status = qp.solve(&p, &q, &[], &[], &gm, &h_rows).ok()?;
            if status.is_ok() {
                *best = (*best).max(qp.solution()[0].max(0.0));
            }
        }
    }
    let feasible = per_axis.iter().copied().fold(0.0, f64::max);
    Some(FeasibleForce { per_axis, feasible })
}
