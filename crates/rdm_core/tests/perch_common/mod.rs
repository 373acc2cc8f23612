//! Random perching instances shared by the perch integration tests, with an analytic
//! feasibility check written from the paper's equations (independent of the QP code).

use nalgebra::{Matrix4, Vector3};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rdm_core::control::perch::{PerchInput, PerchParams};

/// Rotor drag-to-thrust ratio `c` of eq. (9) used for the random layouts.
const DRAG_RATIO: f64 = 0.016;

/// `[F_z, M_x, M_y, M_z]` rows (eq. 8-9) of rotors at `positions` with `normals`.
pub fn allocation_rows(positions: &[Vector3<f64>; 4], normals: &[Vector3<f64>; 4]) -> Matrix4<f64> {
    let mut m = Matrix4::zeros();
    for i in 0..4 {
        let u = normals[i];
        let sigma = if i % 2 == 0 { 1.0 } else { -1.0 };
        let v = positions[i].cross(&u) - DRAG_RATIO * sigma * u;
        m[(0, i)] = u.z;
        m[(1, i)] = v.x;
        m[(2, i)] = v.y;
        m[(3, i)] = v.z;
    }
    m
}

/// A random quadrotor-like layout around the CoG with the foot next to rotors 0 and 1.
pub fn random_instance(rng: &mut ChaCha8Rng, params: &PerchParams) -> PerchInput {
    let mut positions = [Vector3::zeros(); 4];
    let mut normals = [Vector3::zeros(); 4];
    let signs = [(-1.0, -1.0), (-1.0, 1.0), (1.0, 1.0), (1.0, -1.0)];
    for i in 0..4 {
        let (sx, sy) = signs[i];
        positions[i] = Vector3::new(
            sx * rng.random_range(0.15..0.6),
            sy * rng.random_range(0.1..0.4),
            rng.random_range(-0.05..0.05),
        );
        normals[i] = Vector3::new(
            rng.random_range(-0.15..0.15),
            rng.random_range(-0.15..0.15),
            1.0,
        )
        .normalize();
    }
    let foot = Vector3::new(
        rng.random_range(-0.7..-0.3),
        rng.random_range(-0.05..0.05),
        rng.random_range(0.0..0.1),
    );
    let foot_positions = positions.map(|p| p - foot);
    let allocation = allocation_rows(&positions, &normals);
    let foot_allocation = allocation_rows(&foot_positions, &normals);
    let mass = rng.random_range(1.0..6.0);
    let fz = rng.random_range(0.0..30.0);
    let foot_wrench = [
        rng.random_range(-6.0..6.0),
        rng.random_range(-6.0..6.0),
        fz,
        rng.random_range(-0.6..0.6),
        rng.random_range(-0.6..0.6),
        rng.random_range(-1.5..1.5),
    ];
    let previous_foot_wrench = [
        fz + rng.random_range(-3.0..3.0),
        foot_wrench[3],
        foot_wrench[4],
        foot_wrench[5],
    ];
    let max = params.rotor_thrust_max[0];
    let previous_thrust = [0; 4].map(|_| rng.random_range(0.0..max * 0.8));
    PerchInput {
        foot_allocation,
        allocation,
        mass,
        foot_wrench,
        previous_thrust,
        previous_foot_wrench,
        flight_thrust: None,
    }
}

/// Hover thrust `Q̄⁻¹ [m g, 0, 0, 0]` (so `λ_max = λ_rotor_max − hover`, eq. 47).
#[allow(dead_code)] // shared test module: not every test binary uses every helper
pub fn thrust_max(input: &PerchInput, params: &PerchParams) -> Option<[f64; 4]> {
    let inv = input.allocation.try_inverse()?;
    let w = params.gravity * input.mass;
    Some([0, 1, 2, 3].map(|i| params.rotor_thrust_max[i] - w * inv[(i, 0)]))
}

/// Feasibility of eq. (49) under Table VII's masks, as the signed margin of the only coupling
/// constraint: `max over the thrust box of Q̄_perch,z λ − (F_req + e)`; `None` if the box
/// itself is empty by more than `tol`. Positive = feasible.
#[allow(dead_code)] // shared test module: not every test binary uses every helper
pub fn feasibility_margin(input: &PerchInput, params: &PerchParams) -> Option<f64> {
    let lmax = thrust_max(input, params)?;
    let [fx, fy, fz, mx, my, mz] = input.foot_wrench;
    let pz = params.zmp_z;
    let f_req = params
        .epsilon_z
        .max(fx.abs() / params.mu_x)
        .max(fy.abs() / params.mu_y)
        .max(mz.abs() / params.mu_z)
        .max((fx * pz - my).abs() / params.half_size_x)
        .max((fy * pz + mx).abs() / params.half_size_y);
    let e = params.feedback_gain * (input.previous_foot_wrench[0] - fz);
    let mut best = 0.0;
    let mut box_gap = f64::INFINITY;
    for (i, &lmax_i) in lmax.iter().enumerate() {
        let lo = (input.previous_thrust[i] - params.thrust_rate_limit[i]).max(0.0);
        let hi = (input.previous_thrust[i] + params.thrust_rate_limit[i]).min(lmax_i);
        box_gap = box_gap.min(hi - lo);
        let q = if params.perch_rotors[i] {
            input.foot_allocation[(0, i)]
        } else {
            0.0
        };
        best += if q > 0.0 { q * hi } else { q * lo };
    }
    if box_gap < 0.0 {
        return Some(box_gap);
    }
    Some(best - (f_req + e))
}
