//! Rust-side timing loops for `rdm bench`: each one runs the real core step over inputs
//! prepared in Python, timing every call with `std::time::Instant` while the GIL is
//! released, and returns the per-call nanoseconds together with what each step computed
//! (so tests can check that the timed computation is the ordinary one).

use nalgebra::{Matrix3, Matrix4, SMatrix, Vector2};
use numpy::ndarray::{Array1, Array2, Array3};
use numpy::{IntoPyArray, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3, PyReadonlyArray4};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::hint::black_box;
use std::time::Instant;

use rdm_core::control::attitude::{AttitudeControlConfig, SpinalConfig, SpinalStep};
use rdm_core::control::gains::GainSet;
use rdm_core::control::lqi::{LqiConfig, LqiSynthesizer};
use rdm_core::control::perch::{PerchController, PerchParams, PerchStatus};
use rdm_core::control::position::{PositionController, PositionGains, PositionInput, N_VECTORING};
use rdm_core::estimate::{EstimatorConfig, ImuSample};
use rdm_core::pwm::PwmInfo;
use rdm_core::{check_rotor_count, MAX_ROTORS, PERCH_ROTORS};

use crate::errors::RdmError;

fn bad(msg: String) -> PyErr {
    RdmError::new_err(msg)
}

/// Elapsed nanoseconds as i64 (saturating; a step never takes 292 years).
fn nanos(t0: Instant) -> i64 {
    i64::try_from(t0.elapsed().as_nanos()).unwrap_or(i64::MAX)
}

/// Rows of an (n, C) array as fixed arrays; `n` must match.
fn rows<const C: usize>(
    name: &str,
    a: &PyReadonlyArray2<'_, f64>,
    n: usize,
) -> PyResult<Vec<[f64; C]>> {
    let v = a.as_array();
    if v.shape() != [n, C] {
        return Err(bad(format!(
            "`{name}` must have shape ({n}, {C}), got {:?}",
            v.shape()
        )));
    }
    Ok(v.rows()
        .into_iter()
        .map(|r| std::array::from_fn(|j| r[j]))
        .collect())
}

/// Blocks of an (n, R, C) array as fixed-size matrices; `n` must match.
fn blocks<const R: usize, const C: usize>(
    name: &str,
    a: &PyReadonlyArray3<'_, f64>,
    n: usize,
) -> PyResult<Vec<SMatrix<f64, R, C>>> {
    let v = a.as_array();
    if v.shape() != [n, R, C] {
        return Err(bad(format!(
            "`{name}` must have shape ({n}, {R}, {C}), got {:?}",
            v.shape()
        )));
    }
    Ok((0..n)
        .map(|k| SMatrix::from_fn(|i, j| v[[k, i, j]]))
        .collect())
}

fn matrix_rows_to_py<'py, const C: usize>(py: Python<'py>, v: &[[f64; C]]) -> Bound<'py, PyAny> {
    Array2::from_shape_fn((v.len(), C), |(k, j)| v[k][j])
        .into_pyarray(py)
        .into_any()
}

/// An armed, integrating Spinal step configured like the Python `SpinalStep` would be by
/// `set_uav_info(rotors, 16)`, `set_pwm_info_hydrus_example()`, `set_gains`,
/// `set_pinv_inertia`, `flight_config(0)`, `flight_config(160)`.
fn armed_spinal(
    rate_hz: f64,
    gyro_calib_duration_s: f64,
    gains: &GainSet,
    pinv: &[[f64; 3]],
    inertia: [f64; 6],
) -> PyResult<SpinalStep> {
    let rotors = pinv.len();
    let config = SpinalConfig {
        estimator: EstimatorConfig {
            gyro_calib_duration_s,
            ..EstimatorConfig::new(rate_hz)
        },
        control: AttitudeControlConfig {
            rate_hz,
            motor_outputs: rotors,
            ..AttitudeControlConfig::default()
        },
    };
    let mut spinal = SpinalStep::new(config).map_err(|f| bad(format!("{f}: out of range")))?;
    let c = spinal.controller_mut();
    let rejected = |e: rdm_core::control::attitude::CommandError| bad(e.to_string());
    let motor_num = u8::try_from(rotors).map_err(|_| bad(format!("{rotors} rotors")))?;
    c.set_uav_info(motor_num, 16).map_err(rejected)?;
    c.set_pwm_info(PwmInfo::hydrus_example())
        .map_err(rejected)?;
    c.set_gains(gains).map_err(rejected)?;
    c.set_pinv_inertia(pinv, inertia).map_err(rejected)?;
    c.flight_config(0, 0.0).map_err(rejected)?;
    c.flight_config(160, 0.0).map_err(rejected)?;
    Ok(spinal)
}

fn gain_set(a: &PyReadonlyArray3<'_, f64>) -> PyResult<(GainSet, usize)> {
    crate::gains::gain_set_from_view(a.as_array().into_dyn(), None)
}

/// The first `rotors` entries of each row, as an (n, rotors) array.
fn rotor_rows_to_py<'py>(
    py: Python<'py>,
    v: &[[f64; MAX_ROTORS]],
    rotors: usize,
) -> Bound<'py, PyAny> {
    Array2::from_shape_fn((v.len(), rotors), |(k, j)| v[k][j])
        .into_pyarray(py)
        .into_any()
}

/// Times `SpinalStep::step` (estimator + attitude control + PWM) once per row of the
/// inputs. Every `command_every` steps (before the step, untimed) a `four_axis_command`
/// with `command_angles` / `command_base_thrust` is sent, as the PC does. The rotor count is
/// the rows of `gains` (rotors, 4, 3); `pinv` and `command_base_thrust` have as many.
/// Returns a dict `ns` (n,), `duty` (n, rotors), `thrust` (n, rotors), `euler` (n, 3),
/// `invalid` (count of steps whose status was `invalid_input`).
#[pyfunction]
#[allow(clippy::too_many_arguments)]
#[pyo3(signature = (gains, pinv, inertia, now, gyro, acc, mag, voltage, command_every,
                    command_angles, command_base_thrust, rate_hz=200.0,
                    gyro_calib_duration_s=0.0))]
fn time_spinal_steps<'py>(
    py: Python<'py>,
    gains: PyReadonlyArray3<'py, f64>,
    pinv: PyReadonlyArray2<'py, f64>,
    inertia: [f64; 6],
    now: PyReadonlyArray1<'py, f64>,
    gyro: PyReadonlyArray2<'py, f64>,
    acc: PyReadonlyArray2<'py, f64>,
    mag: PyReadonlyArray2<'py, f64>,
    voltage: f64,
    command_every: usize,
    command_angles: [f64; 3],
    command_base_thrust: Vec<f64>,
    rate_hz: f64,
    gyro_calib_duration_s: f64,
) -> PyResult<Bound<'py, PyDict>> {
    let (gains, rotors) = gain_set(&gains)?;
    if command_base_thrust.len() != rotors {
        return Err(bad(format!(
            "`command_base_thrust` must have {rotors} values (the rows of `gains`), got {}",
            command_base_thrust.len()
        )));
    }
    let now: Vec<f64> = now.as_array().to_vec();
    let n = now.len();
    let gyro = rows::<3>("gyro", &gyro, n)?;
    let acc = rows::<3>("acc", &acc, n)?;
    let mag = rows::<3>("mag", &mag, n)?;
    let pinv = rows::<3>("pinv", &pinv, rotors)?;
    let every = command_every.max(1);
    let mut spinal = armed_spinal(rate_hz, gyro_calib_duration_s, &gains, &pinv, inertia)?;
    let (ns, duty, thrust, euler, invalid) = py.detach(move || {
        let mut ns = vec![0i64; n];
        let mut duty = vec![[0.0; MAX_ROTORS]; n];
        let mut thrust = vec![[0.0; MAX_ROTORS]; n];
        let mut euler = vec![[0.0; 3]; n];
        let mut invalid = 0usize;
        for k in 0..n {
            if k % every == 0 {
                // A rejected command is not a timing concern; its effect shows in the outputs.
                let _ = spinal.controller_mut().four_axis_command(
                    command_angles,
                    &command_base_thrust,
                    now[k],
                );
            }
            let imu = ImuSample {
                gyro: gyro[k],
                acc: acc[k],
                mag: mag[k],
            };
            let t0 = Instant::now();
            let out = spinal.step(black_box(now[k]), black_box(&imu), black_box(voltage));
            ns[k] = nanos(t0);
            let out = black_box(out);
            duty[k] = out.control.duty;
            thrust[k] = out.control.thrust;
            euler[k] = out.estimate.euler;
            if out.control.status == rdm_core::control::attitude::ControlStatus::InvalidInput {
                invalid += 1;
            }
        }
        (ns, duty, thrust, euler, invalid)
    });
    let d = PyDict::new(py);
    d.set_item("ns", ns.into_pyarray(py))?;
    d.set_item("duty", rotor_rows_to_py(py, &duty, rotors))?;
    d.set_item("thrust", rotor_rows_to_py(py, &thrust, rotors))?;
    d.set_item("euler", matrix_rows_to_py(py, &euler))?;
    d.set_item("invalid", invalid)?;
    Ok(d)
}

/// Times `LqiSynthesizer::synthesize` (Table V weights, clampGain) over a sequence of
/// configurations `(masses[k], inertias[k], allocations[k])`. `warm`: one synthesizer
/// for the whole sequence (Kleinman from the previous configuration's gains, as at
/// 40 Hz); otherwise the warm start is forgotten (untimed) before every call. Returns a
/// dict `ns` (n,), `k` (n, rotors, 12; NaN where synthesis failed; rotors: the last axis
/// of `allocations` (n, 4, rotors)), `failures`,
/// `fell_back` (warm starts that fell back to the cold method).
#[pyfunction]
#[pyo3(signature = (masses, inertias, allocations, warm=true))]
fn time_lqi_synthesis<'py>(
    py: Python<'py>,
    masses: PyReadonlyArray1<'py, f64>,
    inertias: PyReadonlyArray3<'py, f64>,
    allocations: PyReadonlyArray3<'py, f64>,
    warm: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let masses: Vec<f64> = masses.as_array().to_vec();
    let n = masses.len();
    let inertias = blocks::<3, 3>("inertias", &inertias, n)?;
    let view = allocations.as_array();
    let rotors = view.shape()[2];
    if view.shape()[..2] != [n, 4] || check_rotor_count(rotors).is_err() {
        return Err(bad(format!(
            "`allocations` must have shape ({n}, 4, 1..={MAX_ROTORS}), got {:?}",
            view.shape()
        )));
    }
    let allocations: Vec<SMatrix<f64, 4, MAX_ROTORS>> = (0..n)
        .map(|k| SMatrix::from_fn(|i, j| if j < rotors { view[[k, i, j]] } else { 0.0 }))
        .collect();
    let mut synth =
        LqiSynthesizer::new(LqiConfig::for_rotors(rotors)).map_err(|e| bad(e.to_string()))?;
    type Gain = SMatrix<f64, MAX_ROTORS, 12>;
    let (ns, ks, failures, fell_back) = py.detach(move || {
        let mut ns = vec![0i64; n];
        let mut ks: Vec<Gain> = vec![Gain::from_element(f64::NAN); n];
        let (mut failures, mut fell_back) = (0usize, 0usize);
        for k in 0..n {
            if !warm {
                synth.reset();
            }
            let t0 = Instant::now();
            let result = synth.synthesize(
                black_box(masses[k]),
                black_box(&inertias[k]),
                black_box(&allocations[k]),
            );
            let gains = result.map(|g| (g.k, g.report.fell_back));
            ns[k] = nanos(t0);
            match gains {
                Ok((gain, fell)) => {
                    ks[k] = gain;
                    fell_back += usize::from(fell);
                }
                Err(_) => failures += 1,
            }
        }
        (ns, ks, failures, fell_back)
    });
    let k_array = Array3::from_shape_fn((n, rotors, 12), |(k, i, j)| ks[k][(i, j)]);
    let d = PyDict::new(py);
    d.set_item("ns", ns.into_pyarray(py))?;
    d.set_item("k", k_array.into_pyarray(py))?;
    d.set_item("failures", failures)?;
    d.set_item("fell_back", fell_back)?;
    Ok(d)
}

/// One 40 Hz onboard tick's inputs.
struct TickInput {
    position: PositionInput,
    foot_wrench: [f64; 6],
    foot_allocation: Matrix4<f64>,
    allocation: Matrix4<f64>,
}

/// Times the 40 Hz onboard tick: the position step (eqs. 30-36, Table V gains) followed
/// by the perching controller tick (1 Hz filter + eq. 49 on Clarabel, Table VII
/// parameters), both timed together per tick. The perching controller starts from
/// `initial_thrust`. Returns a dict `ns` (n,), `thrust` (n, 4), `status` (n,) codes into
/// `status_names`, `alpha`, `beta`, `acceleration` (n, 2), `failures` (ticks whose QP
/// status was not solved/almost solved, plus failed position steps),
/// `position_failures`.
#[pyfunction]
#[allow(clippy::too_many_arguments)]
#[pyo3(signature = (position, velocity, target_position, target_velocity, target_yaw,
                    link_rotations, dt, foot_wrench, foot_allocation, allocation, mass,
                    initial_thrust, rate_hz=40.0, cutoff_hz=1.0))]
fn time_onboard_ticks<'py>(
    py: Python<'py>,
    position: PyReadonlyArray2<'py, f64>,
    velocity: PyReadonlyArray2<'py, f64>,
    target_position: PyReadonlyArray2<'py, f64>,
    target_velocity: PyReadonlyArray2<'py, f64>,
    target_yaw: PyReadonlyArray1<'py, f64>,
    link_rotations: PyReadonlyArray4<'py, f64>,
    dt: f64,
    foot_wrench: PyReadonlyArray2<'py, f64>,
    foot_allocation: PyReadonlyArray3<'py, f64>,
    allocation: PyReadonlyArray3<'py, f64>,
    mass: f64,
    initial_thrust: [f64; PERCH_ROTORS],
    rate_hz: f64,
    cutoff_hz: f64,
) -> PyResult<Bound<'py, PyDict>> {
    let yaw: Vec<f64> = target_yaw.as_array().to_vec();
    let n = yaw.len();
    let position = rows::<2>("position", &position, n)?;
    let velocity = rows::<2>("velocity", &velocity, n)?;
    let target_position = rows::<2>("target_position", &target_position, n)?;
    let target_velocity = rows::<2>("target_velocity", &target_velocity, n)?;
    let rotations = link_rotations.as_array();
    if rotations.shape() != [n, N_VECTORING, 3, 3] {
        return Err(bad(format!(
            "`link_rotations` must have shape ({n}, {N_VECTORING}, 3, 3), got {:?}",
            rotations.shape()
        )));
    }
    let wrench = rows::<6>("foot_wrench", &foot_wrench, n)?;
    let foot_allocation = blocks::<4, 4>("foot_allocation", &foot_allocation, n)?;
    let allocation = blocks::<4, 4>("allocation", &allocation, n)?;
    let inputs: Vec<TickInput> = (0..n)
        .map(|k| TickInput {
            position: PositionInput {
                position: Vector2::from(position[k]),
                velocity: Vector2::from(velocity[k]),
                target_position: Vector2::from(target_position[k]),
                target_velocity: Vector2::from(target_velocity[k]),
                target_yaw: yaw[k],
                link_rotations: std::array::from_fn(|u| {
                    Matrix3::from_fn(|i, j| rotations[[k, u, i, j]])
                }),
                dt,
            },
            foot_wrench: wrench[k],
            foot_allocation: foot_allocation[k],
            allocation: allocation[k],
        })
        .collect();
    let mut position_control = PositionController::new(PositionGains::table_v())
        .map_err(|e| bad(format!("position gains: {e:?}")))?;
    let mut perch = PerchController::new(PerchParams::default(), rate_hz, cutoff_hz)
        .map_err(|e| bad(e.to_string()))?;
    perch.reset(initial_thrust);
    struct TickOutput {
        ns: i64,
        thrust: [f64; PERCH_ROTORS],
        status: u8,
        alpha: [f64; N_VECTORING],
        beta: [f64; N_VECTORING],
        acceleration: [f64; 2],
    }
    let (out, failures, position_failures) = py.detach(move || {
        let mut out = Vec::with_capacity(n);
        let (mut failures, mut position_failures) = (0usize, 0usize);
        for input in &inputs {
            let t0 = Instant::now();
            let pos = position_control.step(black_box(&input.position));
            let sol = perch.tick(
                black_box(&input.foot_wrench),
                black_box(&input.foot_allocation),
                black_box(&input.allocation),
                black_box(mass),
                None,
            );
            let ns = nanos(t0);
            let (alpha, beta, acceleration) = match pos {
                Ok(p) => (p.alpha, p.beta, [p.acceleration.x, p.acceleration.y]),
                Err(_) => {
                    position_failures += 1;
                    (
                        [f64::NAN; N_VECTORING],
                        [f64::NAN; N_VECTORING],
                        [f64::NAN; 2],
                    )
                }
            };
            if !sol.status.is_solution() {
                failures += 1;
            }
            let status = PerchStatus::ALL
                .iter()
                .position(|s| *s == sol.status)
                .unwrap_or(usize::MAX) as u8;
            out.push(TickOutput {
                ns,
                thrust: sol.thrust,
                status,
                alpha,
                beta,
                acceleration,
            });
        }
        (out, failures + position_failures, position_failures)
    });
    let d = PyDict::new(py);
    d.set_item(
        "ns",
        Array1::from_iter(out.iter().map(|o| o.ns)).into_pyarray(py),
    )?;
    let thrust: Vec<[f64; PERCH_ROTORS]> = out.iter().map(|o| o.thrust).collect();
    d.set_item("thrust", matrix_rows_to_py(py, &thrust))?;
    d.set_item(
        "status",
        Array1::from_iter(out.iter().map(|o| o.status)).into_pyarray(py),
    )?;
    let names: Vec<&str> = PerchStatus::ALL.iter().map(|s| s.as_str()).collect();
    d.set_item("status_names", names)?;
    let alpha: Vec<[f64; N_VECTORING]> = out.iter().map(|o| o.alpha).collect();
    let beta: Vec<[f64; N_VECTORING]> = out.iter().map(|o| o.beta).collect();
    let acceleration: Vec<[f64; 2]> = out.iter().map(|o| o.acceleration).collect();
    d.set_item("alpha", matrix_rows_to_py(py, &alpha))?;
    d.set_item("beta", matrix_rows_to_py(py, &beta))?;
    d.set_item("acceleration", matrix_rows_to_py(py, &acceleration))?;
    d.set_item("failures", failures)?;
    d.set_item("position_failures", position_failures)?;
    Ok(d)
}

/// `"release"` or `"debug"`: the profile this extension was compiled with (by whether
/// debug assertions are on, which is what distinguishes maturin's two profiles).
#[pyfunction]
fn bench_build_profile() -> &'static str {
    if cfg!(debug_assertions) {
        "debug"
    } else {
        "release"
    }
}

/// Resolution check: nanoseconds of `n` back-to-back `Instant::now()` pairs (the timer's
/// own cost, subtracted by nobody; reported so readers can judge sub-µs figures).
#[pyfunction]
#[pyo3(signature = (n=10_000))]
fn time_timer_overhead<'py>(py: Python<'py>, n: usize) -> Bound<'py, PyAny> {
    let ns = py.detach(move || {
        (0..n)
            .map(|_| {
                let t0 = Instant::now();
                nanos(black_box(t0))
            })
            .collect::<Vec<i64>>()
    });
    ns.into_pyarray(py).into_any()
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(time_spinal_steps, m)?)?;
    m.add_function(wrap_pyfunction!(time_lqi_synthesis, m)?)?;
    m.add_function(wrap_pyfunction!(time_onboard_ticks, m)?)?;
    m.add_function(wrap_pyfunction!(bench_build_profile, m)?)?;
    m.add_function(wrap_pyfunction!(time_timer_overhead, m)?)?;
    Ok(())
}
