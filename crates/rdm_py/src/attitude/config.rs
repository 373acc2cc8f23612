//! The controller's keyword options and its event list, as the Python classes take and give
//! them.

use pyo3::prelude::*;
use pyo3::types::PyList;
use rdm_core::control::attitude::{AntiWindup, AttitudeControlConfig, AttitudeOutput, SpinalEvent};
use rdm_core::pwm::VoltageGuard;

use crate::errors::RdmError;

/// The keyword arguments of `AttitudeController` / `SpinalStep` that configure the
/// controller. `None` booleans follow `firmware_exact` (on unless it is set).
pub(crate) struct ControlOptions {
    pub rate_hz: f64,
    pub firmware_exact: bool,
    pub anti_windup: Option<bool>,
    pub integral_limit: f64,
    pub command_timeout_s: f64,
    pub max_tilt_rad: f64,
    pub force_landing_rate: f64,
    pub voltage_guard: Option<bool>,
    pub battery_cells: u32,
    pub cell_voltage_range: (f64, f64),
    pub saturate_commands: Option<bool>,
    pub bound_alpha: Option<bool>,
    pub motor_outputs: usize,
}

/// A checked controller configuration from the keyword options.
pub(crate) fn control_config(o: &ControlOptions) -> PyResult<AttitudeControlConfig> {
    let guarded = !o.firmware_exact;
    let config = AttitudeControlConfig {
        rate_hz: o.rate_hz,
        anti_windup: if o.anti_windup.unwrap_or(guarded) {
            AntiWindup::ClampAndConditional {
                limit: o.integral_limit,
            }
        } else {
            AntiWindup::Off
        },
        command_timeout_s: o.command_timeout_s,
        max_tilt_rad: o.max_tilt_rad,
        force_landing_rate: o.force_landing_rate,
        voltage_guard: if o.voltage_guard.unwrap_or(guarded) {
            VoltageGuard::CellWindow {
                cells: o.battery_cells,
                min_cell_v: o.cell_voltage_range.0,
                max_cell_v: o.cell_voltage_range.1,
            }
        } else {
            VoltageGuard::Off
        },
        saturate_commands: o.saturate_commands.unwrap_or(guarded),
        bound_alpha: o.bound_alpha.unwrap_or(guarded),
        motor_outputs: o.motor_outputs,
    };
    config.validate().map_err(|field| {
        let field = match field {
            "voltage_guard.cells" => "battery_cells (0..=24)",
            "voltage_guard.min_cell_v" => "cell_voltage_range[0] (> 0)",
            "voltage_guard.max_cell_v" => "cell_voltage_range[1] (> cell_voltage_range[0])",
            "motor_outputs" => "motor_outputs (1..=MAX_ROTORS = 8)",
            other => other,
        };
        RdmError::new_err(format!("{field}: out of range"))
    })?;
    Ok(config)
}

/// The events of a step as `(kind, value)` tuples.
pub(crate) fn events_list<'py>(
    py: Python<'py>,
    out: &AttitudeOutput,
) -> PyResult<Bound<'py, PyList>> {
    let list = PyList::empty(py);
    for event in out.events.iter() {
        let item: (&str, Py<PyAny>) = match event {
            SpinalEvent::Ack(cmd) => ("ack", cmd.to_wire().into_pyobject(py)?.into_any().unbind()),
            SpinalEvent::FailsafeCommandTimeout => ("failsafe_timeout", py.None()),
            SpinalEvent::FailsafeTilt => ("failsafe_tilt", py.None()),
            SpinalEvent::FailsafeCommandTilt => ("failsafe_command_tilt", py.None()),
            SpinalEvent::Rejected(e) => (
                "rejected",
                e.to_string().into_pyobject(py)?.into_any().unbind(),
            ),
            SpinalEvent::VoltageRejected => ("voltage_rejected", py.None()),
            SpinalEvent::CommandSaturated => ("command_saturated", py.None()),
            SpinalEvent::NonFiniteOutput => ("non_finite_output", py.None()),
            SpinalEvent::AlphaBounded => ("alpha_bounded", py.None()),
        };
        list.append(item)?;
    }
    if out.events.dropped() > 0 {
        list.append(("events_dropped", out.events.dropped()))?;
    }
    Ok(list)
}
