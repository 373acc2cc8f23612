//! The rows of the perching QP (eq. 49) a tick hands to its solvers, read back through
//! `PerchQp::a_csc` and `PerchQp::b`, against the paper's constraints (38)-(48) written out
//! here one row at a time, `λ_max` of eq. (47) with `Q̄` inverted by nalgebra's
//! `try_inverse`, and the wrench a rate-limited thrust commands (eq. 38) as a matrix product.

// Index loops over parallel per-rotor arrays read clearer than zipped iterators here.
#![allow(clippy::needless_range_loop)]

#[allow(dead_code)] // the random instances serve the other perch tests
mod perch_common;

use nalgebra::{Matrix4, Vector3, Vector4};
use perch_common::allocation_rows;
use rdm_core::control::perch::{PerchInput, PerchParams, PerchQp, PerchStatus, N_ROWS, N_VARS};

const FZ: usize = 4;
const MX: usize = 5;
const MY: usize = 6;
const MZ: usize = 7;

/// A quadrotor-like layout with the foot 0.4 m behind the CoG; `mirror` swaps the sides.
fn layout(mirror: bool) -> (Matrix4<f64>, Matrix4<f64>) {
    let side = if mirror { -1.0 } else { 1.0 };
    let positions = [
        Vector3::new(-0.3, -0.2 * side, 0.0),
        Vector3::new(-0.3, 0.2 * side, 0.0),
        Vector3::new(0.3, 0.25 * side, 0.02),
        Vector3::new(0.3, -0.2 * side, 0.0),
    ];
    let normals = [
        Vector3::z(),
        Vector3::z(),
        Vector3::new(0.05, 0.0, 1.0).normalize(),
        Vector3::new(0.0, -0.04, 1.0).normalize(),
    ];
    let foot = Vector3::new(-0.4, 0.0, 0.05);
    (
        allocation_rows(&positions.map(|p| p - foot), &normals),
        allocation_rows(&positions, &normals),
    )
}

fn base_params() -> PerchParams {
    PerchParams {
        zmp_z: 0.05,
        rotor_thrust_max: [30.0, 28.0, 26.0, 24.0],
        thrust_rate_limit: [5.0, 4.0, 6.0, 3.0],
        feedback_gain: 0.7,
        ..PerchParams::default()
    }
}

fn input() -> PerchInput {
    let (foot_allocation, allocation) = layout(false);
    PerchInput {
        foot_allocation,
        allocation,
        mass: 2.5,
        foot_wrench: [0.3, -0.2, 4.0, 0.02, -0.01, 0.005],
        previous_thrust: [3.0, 2.5, 7.0, 6.0],
        previous_foot_wrench: [4.5, 0.0, 0.0, 0.0],
        flight_thrust: None,
    }
}

/// Eq. (47): `λ_max = λ_rotor_max − Q̄⁻¹ [m g, 0, 0, 0]`.
fn thrust_max(params: &PerchParams, input: &PerchInput) -> [f64; 4] {
    let hover = input.allocation.try_inverse().unwrap()
        * Vector4::new(input.mass * params.gravity, 0.0, 0.0, 0.0);
    std::array::from_fn(|i| params.rotor_thrust_max[i] - hover[i])
}

/// The rows of the module table, unscaled: (coefficients of `[λ; w]`, right side).
fn table(params: &PerchParams, input: &PerchInput) -> Vec<([f64; N_VARS], f64)> {
    let [fx, fy, fz, mx, my, mz] = input.foot_wrench;
    let measured = [fz, mx, my, mz];
    let mut perch = input.foot_allocation;
    for i in 0..4 {
        if !params.perch_rotors[i] {
            perch.column_mut(i).fill(0.0);
        }
    }
    let row = |entries: &[(usize, f64)], rhs: f64| {
        let mut a = [0.0; N_VARS];
        for &(c, v) in entries {
            a[c] = v;
        }
        (a, rhs)
    };
    let mut rows = Vec::new();
    for k in 0..4 {
        // Eq. (38) merged: Q̄_perch,k λ − w_k = κ (W_{t−1,k} − W̃_k); else w_k = W̃_k.
        if params.wrench_mask[k] {
            let mut entries: Vec<(usize, f64)> = (0..4).map(|i| (i, perch[(k, i)])).collect();
            entries.push((4 + k, -1.0));
            let rhs = params.feedback_gain * (input.previous_foot_wrench[k] - measured[k]);
            rows.push(row(&entries, rhs));
        } else {
            rows.push(row(&[(4 + k, 1.0)], measured[k]));
        }
    }
    let (hx, hy, pz) = (params.half_size_x, params.half_size_y, params.zmp_z);
    rows.push(row(&[(FZ, -1.0)], -params.epsilon_z)); // (39)
    rows.push(row(&[(FZ, -params.mu_x)], -fx.abs())); // (40) x
    rows.push(row(&[(FZ, -params.mu_y)], -fy.abs())); // (40) y
    rows.push(row(&[(MZ, 1.0), (FZ, -params.mu_z)], 0.0)); // (41)
    rows.push(row(&[(MZ, -1.0), (FZ, -params.mu_z)], 0.0));
    rows.push(row(&[(FZ, -hx), (MY, -1.0)], -fx * pz)); // (42), (43)
    rows.push(row(&[(FZ, -hx), (MY, 1.0)], fx * pz));
    rows.push(row(&[(FZ, -hy), (MX, 1.0)], -fy * pz)); // (42), (44)
    rows.push(row(&[(FZ, -hy), (MX, -1.0)], fy * pz));
    let max = thrust_max(params, input);
    for i in 0..4 {
        rows.push(row(&[(i, -1.0)], 0.0)); // (45), (46)
    }
    for i in 0..4 {
        rows.push(row(&[(i, 1.0)], max[i])); // (47)
    }
    let (previous, rate) = (input.previous_thrust, params.thrust_rate_limit);
    for i in 0..4 {
        rows.push(row(&[(i, 1.0)], previous[i] + rate[i])); // (48)
    }
    for i in 0..4 {
        rows.push(row(&[(i, -1.0)], -previous[i] + rate[i]));
    }
    rows
}

/// Which entries of `A` exist: rows 0-3 every thrust and their own `w`, whatever the mask.
fn expected_pattern(row: usize, col: usize) -> bool {
    match row {
        0..=3 => col < 4 || col == 4 + row,
        4..=6 => col == FZ,
        7 | 8 => col == FZ || col == MZ,
        9 | 10 => col == FZ || col == MY,
        11 | 12 => col == FZ || col == MX,
        _ => col == (row - 13) % 4,
    }
}

fn dense_a(qp: &PerchQp) -> ([[f64; N_VARS]; N_ROWS], [[bool; N_VARS]; N_ROWS]) {
    let (colptr, rowval, nzval) = qp.a_csc();
    let mut a = [[0.0; N_VARS]; N_ROWS];
    let mut present = [[false; N_VARS]; N_ROWS];
    for col in 0..N_VARS {
        for k in colptr[col]..colptr[col + 1] {
            a[rowval[k]][col] = nzval[k];
            present[rowval[k]][col] = true;
        }
    }
    (a, present)
}

#[test]
fn a_and_b_are_the_table_rows_scaled_and_normalised() {
    let params = base_params();
    let input = input();
    let mut qp = PerchQp::new(params.clone()).unwrap();
    let s = qp.variable_scale();
    assert_eq!(s, 30.0);
    let solution = qp.solve(&input);
    assert!(
        solution.status.is_solution() && solution.status != PerchStatus::RateLimited,
        "{:?}",
        solution.status
    );
    let (a, present) = dense_a(&qp);
    let b = qp.b();
    let rows = table(&params, &input);
    assert_eq!(rows.len(), N_ROWS);
    for (r, (coefficients, rhs)) in rows.iter().enumerate() {
        // Variables are x / s, so the right side is divided by s; then every row by its
        // largest |coefficient|.
        let norm = coefficients.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
        assert!(norm > 0.0);
        for c in 0..N_VARS {
            assert_eq!(present[r][c], expected_pattern(r, c), "pattern ({r}, {c})");
            let expected = coefficients[c] / norm;
            assert!(
                (a[r][c] - expected).abs() < 1e-12,
                "A[{r}][{c}] {} vs {expected}",
                a[r][c]
            );
        }
        let expected = rhs / s / norm;
        assert!(
            (b[r] - expected).abs() < 1e-12,
            "b[{r}] {} vs {expected}",
            b[r]
        );
    }
    let max = thrust_max(&params, &input);
    for i in 0..4 {
        assert!((solution.thrust_max[i] - max[i]).abs() < 1e-9, "λ_max {i}");
    }
}

#[test]
fn a_rate_limited_tick_opens_the_rate_rows_and_reports_the_commanded_wrench() {
    // ε_z beyond one rate step from zero thrust: infeasible with eq. (48), so the rows
    // 21-28 become λ ≤ max(λ_max, 0) + δ and −λ ≤ δ, and the reported wrench is what the
    // applied thrust commands through eq. (38).
    let params = PerchParams {
        epsilon_z: 12.0,
        ..base_params()
    };
    let input = PerchInput {
        previous_thrust: [0.0; 4],
        foot_wrench: [0.1, -0.05, 0.5, 0.02, -0.01, 0.005],
        previous_foot_wrench: [1.5, 0.0, 0.0, 0.0],
        ..input()
    };
    let mut qp = PerchQp::new(params.clone()).unwrap();
    let s = qp.variable_scale();
    let solution = qp.solve(&input);
    assert_eq!(solution.status, PerchStatus::RateLimited);
    let b = qp.b();
    let max = thrust_max(&params, &input);
    for i in 0..4 {
        let rate = params.thrust_rate_limit[i];
        let high = (max[i].max(0.0) + rate) / s;
        assert!(
            (b[21 + i] - high).abs() < 1e-12,
            "b[{}] {} vs {high}",
            21 + i,
            b[21 + i]
        );
        assert!(
            (b[25 + i] - rate / s).abs() < 1e-12,
            "b[{}] {}",
            25 + i,
            b[25 + i]
        );
    }
    let mut perch = input.foot_allocation;
    perch.column_mut(2).fill(0.0);
    perch.column_mut(3).fill(0.0);
    let produced = perch * Vector4::from(solution.thrust);
    let measured = [0.5, 0.02, -0.01, 0.005];
    let fz = produced[0] - params.feedback_gain * (input.previous_foot_wrench[0] - measured[0]);
    assert!(produced[0] > 1.0, "the perch rotors press: {produced}");
    assert!(
        (solution.foot_wrench[0] - fz).abs() < 1e-9,
        "{:?}",
        solution.foot_wrench
    );
    assert_eq!(solution.foot_wrench[1..], measured[1..]);
}

/// A field's name and how to make it non-finite.
type Spoil = (&'static str, fn(&mut PerchInput));

#[test]
fn a_non_finite_value_in_any_input_field_is_refused() {
    let params = base_params();
    let mut qp = PerchQp::new(params).unwrap();
    let cases: [Spoil; 7] = [
        ("foot_allocation", |i| i.foot_allocation[(2, 1)] = f64::NAN),
        ("allocation", |i| i.allocation[(3, 0)] = f64::INFINITY),
        ("mass", |i| i.mass = f64::NAN),
        ("foot_wrench", |i| i.foot_wrench[4] = f64::NEG_INFINITY),
        ("previous_thrust", |i| i.previous_thrust[2] = f64::NAN),
        ("previous_foot_wrench", |i| {
            i.previous_foot_wrench[3] = f64::NAN
        }),
        ("flight_thrust", |i| {
            i.flight_thrust = Some([1.0, f64::NAN, 1.0, 1.0])
        }),
    ];
    for (name, spoil) in cases {
        let mut bad = input();
        spoil(&mut bad);
        let solution = qp.solve(&bad);
        assert_eq!(solution.status, PerchStatus::NonFiniteInput, "{name}");
        assert!(solution.thrust.iter().all(|v| v.is_finite()), "{name}");
    }
}

#[test]
fn a_controlled_row_with_a_negative_own_entry_is_still_independent() {
    // F_z and M_x controlled, rotors mirrored so Q̄_perch's rows are [1, 1, 0, 0] and
    // [0.2, −0.2, 0, 0]: with [s e3; s e4] below them the rows are orthogonal, their Gram
    // matrix diag(2, 0.08, 2, 2) positive definite, though the matrix itself is indefinite.
    let params = PerchParams {
        wrench_mask: [true, true, false, false],
        ..base_params()
    };
    let (foot_allocation, allocation) = layout(true);
    assert!(foot_allocation[(1, 0)] > 0.1 && foot_allocation[(1, 1)] < -0.1);
    let input = PerchInput {
        foot_allocation,
        allocation,
        foot_wrench: [0.0, 0.0, 5.0, 0.0, 0.0, 0.0],
        previous_foot_wrench: [5.0, 0.0, 0.0, 0.0],
        ..input()
    };
    let mut qp = PerchQp::new(params.clone()).unwrap();
    let solution = qp.solve(&input);
    assert!(solution.status.is_solution(), "{:?}", solution.status);
    // One perch rotor cannot control both F_z and M_x: its rows [1, 0, 0, 0] and
    // [0.2, 0, 0, 0] are dependent and the tick is refused.
    let params = PerchParams {
        perch_rotors: [true, false, false, false],
        ..params
    };
    let mut qp = PerchQp::new(params).unwrap();
    assert_eq!(qp.solve(&input).status, PerchStatus::SingularAllocation);
}
