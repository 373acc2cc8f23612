//! The flight part of one 40 Hz control tick in one call: the horizontal position loop
//! (eqs. 30-36), the choice between its vectoring angles and the joint targets per unit, and
//! the PC-side altitude/yaw axes (JSK sec. 4). `ControlPipeline.step` made the same calls
//! with Python in between (five array conversions, a dict, a loop over the units); this is
//! that code's arithmetic in the same order, so the outputs are the same floats
//! (`tests/test_flight_axes.py` compares both forms bit for bit).

use nalgebra::{Matrix3, Vector2};
use numpy::ndarray::{Dimension, Ix1, Ix3, IxDyn};
use numpy::{PyArray, PyArrayMethods, PyReadonlyArray};
use pyo3::prelude::*;
use pyo3::types::PyTuple;

use rdm_core::control::lqi::{PcAxisErrors, RotorVector};
use rdm_core::control::position::{PositionInput, N_VECTORING};
use rdm_core::MAX_ROTORS;

use crate::gains::gain_set_from_view;
use crate::lqi::{head_to_py, lqi_error, PcAxisController};
use crate::position::{position_error, PositionController};

/// What one call returns: roll and pitch targets, the yaw term, alpha, beta and applied per
/// vectoring unit, how many units fell back to the joint targets, the base thrust array and
/// the yaw rotor.
type FlightAxes<'py> = (
    f64,
    f64,
    f64,
    Bound<'py, PyTuple>,
    Bound<'py, PyTuple>,
    Bound<'py, PyTuple>,
    usize,
    Bound<'py, PyAny>,
    Option<usize>,
);

/// A read-only view of `value` if it is a float64 array of dimension `D` that nothing
/// borrows for writing; None for anything else.
fn readonly<'py, D: Dimension>(value: &Bound<'py, PyAny>) -> Option<PyReadonlyArray<'py, f64, D>> {
    value.cast::<PyArray<f64, D>>().ok()?.try_readonly().ok()
}

/// Up to `N_VECTORING` `(alpha joint, beta joint)` index pairs of a sequence (a fixed array,
/// so the 40 Hz call allocates none for them) and how many; None for anything else.
fn unit_joints(value: &Bound<'_, PyAny>) -> Option<([(usize, usize); N_VECTORING], usize)> {
    let mut pairs = [(0, 0); N_VECTORING];
    let mut n = 0;
    for item in value.try_iter().ok()? {
        let slot = pairs.get_mut(n)?;
        *slot = item.ok()?.extract().ok()?;
        n += 1;
    }
    Some((pairs, n))
}

/// The values of a float64 vector of exactly `len` (<= `N`) values, zeros after them; None
/// for anything else.
fn head<const N: usize>(value: &Bound<'_, PyAny>, len: usize) -> Option<[f64; N]> {
    let view = readonly::<Ix1>(value)?;
    let v = view.as_array();
    if v.len() != len || len > N {
        return None;
    }
    Some(std::array::from_fn(|i| if i < len { v[i] } else { 0.0 }))
}

/// `ControlPipeline.step`'s flight part (see the module docs). `held`: perched (the
/// horizontal loop at zero error, the z loop at zero error). Returns None, having changed
/// nothing, when an input is not of the form this path reads (float64 vectors of 3 values,
/// (N_VECTORING, 3, 3) rotations, (rotors, 4, 3) gains and as many feed-forward, a float64
/// joint vector): the caller then runs the plain form, which converts or raises as before.
/// Errors of the controllers themselves are raised as the plain form raises them.
#[pyfunction]
#[allow(clippy::too_many_arguments)]
#[pyo3(signature = (position_controller, pc_axes, gains, state_position, state_velocity,
                    state_yaw, setpoint_position, setpoint_velocity, setpoint_yaw,
                    link_rotations, joint_targets, vectoring_joints, feed_forward, held,
                    vectoring, min_nz, dt))]
fn flight_axes<'py>(
    py: Python<'py>,
    position_controller: &Bound<'py, PositionController>,
    pc_axes: &Bound<'py, PcAxisController>,
    gains: &Bound<'py, PyAny>,
    state_position: &Bound<'py, PyAny>,
    state_velocity: &Bound<'py, PyAny>,
    state_yaw: &Bound<'py, PyAny>,
    setpoint_position: &Bound<'py, PyAny>,
    setpoint_velocity: &Bound<'py, PyAny>,
    setpoint_yaw: &Bound<'py, PyAny>,
    link_rotations: &Bound<'py, PyAny>,
    joint_targets: &Bound<'py, PyAny>,
    vectoring_joints: &Bound<'py, PyAny>,
    feed_forward: &Bound<'py, PyAny>,
    held: &Bound<'py, PyAny>,
    vectoring: &Bound<'py, PyAny>,
    min_nz: f64,
    dt: f64,
) -> PyResult<Option<FlightAxes<'py>>> {
    // Every input read (or refused) before anything steps; the controllers borrowed first
    // (a borrow held elsewhere: the plain form, which reports it as it always has).
    let (Ok(mut position_controller), Ok(mut pc_axes)) = (
        position_controller.try_borrow_mut(),
        pc_axes.try_borrow_mut(),
    ) else {
        return Ok(None);
    };
    // truth values as Python's `if` takes them (the plain form's `held` and `vectoring and`)
    let (Ok(held), Ok(vectoring)) = (held.is_truthy(), vectoring.is_truthy()) else {
        return Ok(None);
    };
    let (Some(p), Some(v), Some(sp), Some(sv)) = (
        head::<3>(state_position, 3),
        head::<3>(state_velocity, 3),
        head::<3>(setpoint_position, 3),
        head::<3>(setpoint_velocity, 3),
    ) else {
        return Ok(None);
    };
    let (Ok(state_yaw), Ok(setpoint_yaw)) =
        (state_yaw.extract::<f64>(), setpoint_yaw.extract::<f64>())
    else {
        return Ok(None);
    };
    let Some((joint_pairs, n)) = unit_joints(vectoring_joints) else {
        return Ok(None);
    };
    let vectoring_joints = &joint_pairs[..n];
    let Some(rotations) = readonly::<Ix3>(link_rotations) else {
        return Ok(None);
    };
    let rotations = rotations.as_array();
    if rotations.shape() != [N_VECTORING, 3, 3] {
        return Ok(None);
    }
    let Some(gains) = readonly::<IxDyn>(gains) else {
        return Ok(None);
    };
    let Ok((gains, rotors)) = gain_set_from_view(gains.as_array(), None) else {
        return Ok(None);
    };
    let Some(ff) = head::<MAX_ROTORS>(feed_forward, rotors) else {
        return Ok(None);
    };
    let Some(targets) = readonly::<Ix1>(joint_targets) else {
        return Ok(None);
    };
    let targets = targets.as_array();
    let n_targets = targets.len();
    if vectoring_joints
        .iter()
        .any(|&(a, b)| a >= n_targets || b >= n_targets)
    {
        return Ok(None);
    }

    // 4's inputs (PC-side axes; perched, the z loop is held at zero error, its integral
    // kept). Where the axes would refuse them, the plain form runs instead: it raises after
    // the position step has run and the singular units were counted, as before.
    let (z, z_rate) = if held {
        (0.0, 0.0)
    } else {
        (sp[2] - p[2], sv[2] - v[2])
    };
    let yaw = setpoint_yaw - state_yaw;
    let errors = PcAxisErrors {
        z,
        z_rate,
        yaw: yaw.sin().atan2(yaw.cos()), // wrap_angle: atan2(sin a, cos a)
    };
    let ff = RotorVector::from_fn(|i, _| ff[i]);
    let axes_accept = dt.is_finite()
        && dt > 0.0
        && [errors.z, errors.z_rate, errors.yaw]
            .iter()
            .all(|e| e.is_finite())
        && ff.iter().all(|f| f.is_finite());
    if !axes_accept {
        return Ok(None);
    }

    // 3. position control: perched, the loop is held at zero error (ControlPipeline.step).
    let position = Vector2::new(p[0], p[1]);
    let velocity = if held {
        Vector2::zeros()
    } else {
        Vector2::new(v[0], v[1])
    };
    let input = PositionInput {
        position,
        velocity,
        target_position: if held {
            position
        } else {
            Vector2::new(sp[0], sp[1])
        },
        target_velocity: if held {
            velocity
        } else {
            Vector2::new(sv[0], sv[1])
        },
        target_yaw: setpoint_yaw,
        link_rotations: std::array::from_fn(|i| Matrix3::from_fn(|a, b| rotations[[i, a, b]])),
        dt,
    };
    let out = position_controller
        .inner
        .step(&input)
        .map_err(position_error)?;
    let (mut alpha, mut beta, mut applied) =
        ([0.0; N_VECTORING], [0.0; N_VECTORING], [false; N_VECTORING]);
    let mut singular = 0;
    for (i, &(ja, jb)) in vectoring_joints.iter().enumerate() {
        let ok = vectoring && out.direction[i][2].abs() >= min_nz;
        if !ok && vectoring {
            singular += 1;
        }
        alpha[i] = if ok { out.alpha[i] } else { targets[ja] };
        beta[i] = if ok { out.beta[i] } else { targets[jb] };
        applied[i] = ok;
    }

    // 4. PC-side axes (their inputs were checked above: this step does not fail)
    let command = pc_axes
        .inner
        .step(&gains, &errors, &ff, dt)
        .map_err(lqi_error)?;
    Ok(Some((
        out.roll,
        out.pitch,
        command.yaw_command,
        PyTuple::new(py, &alpha[..n])?,
        PyTuple::new(py, &beta[..n])?,
        PyTuple::new(py, &applied[..n])?,
        singular,
        head_to_py(py, &command.base_thrust, rotors),
        command.yaw_rotor,
    )))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(flight_axes, m)?)?;
    Ok(())
}
