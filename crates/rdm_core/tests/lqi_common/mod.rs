//! Random, physically plausible robot quantities for the LQI tests (no model module).

#![allow(dead_code)]

use nalgebra::{Matrix3, Rotation3, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rdm_core::control::lqi::Allocation;

/// Thrust-to-drag-moment ratio c of eq. (9) (typical small propeller).
pub const DRAG_RATIO: f64 = 0.016;

pub fn rng(seed: u64) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(seed)
}

/// Rotors of [`random_robot`] (the paper's RDM count).
pub const ROTORS: usize = 4;

/// Mass, inertia and allocation of a random four-rotor layout ([`random_robot_with`]).
pub fn random_robot(rng: &mut ChaCha8Rng) -> (f64, Matrix3<f64>, Allocation) {
    random_robot_with(rng, ROTORS)
}

/// Mass, inertia and allocation of a random layout of `rotors` rotors: within 0.8 m of the
/// CoG, thrust axes tilted up to 0.3 rad, alternating spin (eqs. 8-9).
pub fn random_robot_with(rng: &mut ChaCha8Rng, rotors: usize) -> (f64, Matrix3<f64>, Allocation) {
    let mass = rng.random_range(1.5..8.0);
    let principal = Vector3::new(
        rng.random_range(0.02..0.3),
        rng.random_range(0.02..0.6),
        rng.random_range(0.05..0.8),
    );
    let rotation = Rotation3::from_euler_angles(
        rng.random_range(-0.3..0.3),
        rng.random_range(-0.3..0.3),
        rng.random_range(-3.0..3.0),
    );
    let inertia = rotation * Matrix3::from_diagonal(&principal) * rotation.transpose();
    let mut allocation = Allocation::zeros();
    for i in 0..rotors {
        let angle = i as f64 * std::f64::consts::TAU / rotors as f64 + rng.random_range(-0.4..0.4);
        let radius = rng.random_range(0.2..0.8);
        let p = Vector3::new(
            radius * angle.cos(),
            radius * angle.sin(),
            rng.random_range(-0.05..0.05),
        );
        let u = (Rotation3::from_euler_angles(
            rng.random_range(-0.3..0.3),
            rng.random_range(-0.3..0.3),
            0.0,
        ) * Vector3::z())
        .normalize();
        let sigma = if i % 2 == 0 { 1.0 } else { -1.0 };
        let v = p.cross(&u) - DRAG_RATIO * sigma * u;
        allocation[(0, i)] = u.z;
        allocation[(1, i)] = v.x;
        allocation[(2, i)] = v.y;
        allocation[(3, i)] = v.z;
    }
    (mass, inertia, allocation)
}

/// A slightly moved configuration (joint motion between two gain updates).
pub fn perturb(
    rng: &mut ChaCha8Rng,
    robot: &(f64, Matrix3<f64>, Allocation),
    size: f64,
) -> (f64, Matrix3<f64>, Allocation) {
    let (mass, inertia, allocation) = robot;
    let tweak = Matrix3::from_fn(|_, _| rng.random_range(-size..size));
    let inertia = inertia + (tweak + tweak.transpose()) * 0.5 * inertia.norm() * 0.1;
    let allocation = allocation.map(|v| v * (1.0 + rng.random_range(-size..size)));
    (*mass, inertia, allocation)
}
