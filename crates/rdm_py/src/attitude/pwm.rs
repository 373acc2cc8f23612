//! Bindings of `rdm_core::pwm`: the thrust -> duty converter and the duty encodings.

use numpy::{PyArray1, PyReadonlyArray1, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;
use rdm_core::pwm::{
    duty_to_can_value, duty_to_dshot, duty_to_report, MotorInfo, PwmConverter, PwmInfo, PwmMode,
    VoltageGuard, CELL_MAX_V, CELL_MIN_V, MAX_MOTOR_INFO,
};

use crate::errors::RdmError;

/// Builds a checked `PwmInfo`; `motor_info` rows are (voltage, max_thrust, p0, p1, p2, p3, p4).
pub(crate) fn pwm_info(
    min_pwm: f64,
    max_pwm: f64,
    min_thrust: f64,
    force_landing_thrust: f64,
    mode: u8,
    motor_info: &PyReadonlyArray2<'_, f64>,
) -> PyResult<PwmInfo> {
    let mode = PwmMode::from_wire(mode)
        .ok_or_else(|| RdmError::new_err(format!("mode: {mode} is not 0 (SQRT) or 1 (POLY)")))?;
    if motor_info.ndim() != 2 || motor_info.shape()[1] != 7 {
        return Err(RdmError::new_err(
            "motor_info: need shape (k, 7): voltage, max_thrust, p0..p4",
        ));
    }
    let rows = motor_info.shape()[0];
    if rows == 0 || rows > MAX_MOTOR_INFO {
        return Err(RdmError::new_err(format!(
            "motor_info: need 1..={MAX_MOTOR_INFO} rows, got {rows}"
        )));
    }
    let a = motor_info.as_array();
    let mut curves = [MotorInfo::default(); MAX_MOTOR_INFO];
    for (k, curve) in curves.iter_mut().enumerate().take(rows) {
        *curve = MotorInfo {
            voltage: a[[k, 0]],
            max_thrust: a[[k, 1]],
            polynomial: [a[[k, 2]], a[[k, 3]], a[[k, 4]], a[[k, 5]], a[[k, 6]]],
        };
    }
    PwmInfo::new(
        min_pwm,
        max_pwm,
        min_thrust,
        force_landing_thrust,
        mode,
        &curves[..rows],
    )
    .map_err(|e| RdmError::new_err(e.to_string()))
}

/// Thrust -> duty conversion as Spinal's `pwmConversion` (see docs/spinal.md).
///
/// `PwmConverter(min_pwm, max_pwm, min_thrust, force_landing_thrust, mode, motor_info, *,
/// voltage_guard=True, battery_cells=0, cell_voltage_range=(3.0, 4.45))`, mode 0 = SQRT,
/// 1 = POLY; `motor_info` rows (voltage, max_thrust, p0, p1, p2, p3, p4). The voltage guard
/// rejects a voltage outside cells x cell_voltage_range (cells 0: from the reference curves)
/// and uses the last good one; `voltage_guard=False` is firmware-exact.
#[pyclass(module = "rdm._rdm", name = "PwmConverter")]
pub struct PyPwmConverter {
    inner: PwmConverter,
}

#[pymethods]
impl PyPwmConverter {
    #[new]
    #[pyo3(signature = (min_pwm, max_pwm, min_thrust, force_landing_thrust, mode, motor_info,
                        *, voltage_guard = true, battery_cells = 0,
                        cell_voltage_range = (CELL_MIN_V, CELL_MAX_V)))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        min_pwm: f64,
        max_pwm: f64,
        min_thrust: f64,
        force_landing_thrust: f64,
        mode: u8,
        motor_info: PyReadonlyArray2<'_, f64>,
        voltage_guard: bool,
        battery_cells: u32,
        cell_voltage_range: (f64, f64),
    ) -> PyResult<Self> {
        let info = pwm_info(
            min_pwm,
            max_pwm,
            min_thrust,
            force_landing_thrust,
            mode,
            &motor_info,
        )?;
        let guard = if voltage_guard {
            VoltageGuard::CellWindow {
                cells: battery_cells,
                min_cell_v: cell_voltage_range.0,
                max_cell_v: cell_voltage_range.1,
            }
        } else {
            VoltageGuard::Off
        };
        let inner =
            PwmConverter::with_guard(info, guard).map_err(|e| RdmError::new_err(e.to_string()))?;
        Ok(Self { inner })
    }

    /// Re-selects the reference if more than 0.5 s passed since the last selection.
    fn update_voltage(&mut self, voltage: f64, now_s: f64) -> bool {
        self.inner.update_voltage(voltage, now_s)
    }

    /// Selects the reference for `voltage` now; False when the voltage was rejected (the
    /// last good one is then used, guard on).
    fn force_voltage(&mut self, voltage: f64) -> bool {
        self.inner.force_voltage(voltage)
    }

    /// Sets the rotor divider (2 for DRAGON dual rotors).
    fn set_rotor_divider(&mut self, rotor_divider: f64) {
        self.inner.set_rotor_divider(rotor_divider);
    }

    /// Unclamped duties of thrusts (firmware `convert`).
    fn raw_duty<'py>(
        &self,
        py: Python<'py>,
        thrust: PyReadonlyArray1<'py, f64>,
    ) -> Bound<'py, PyArray1<f64>> {
        let out: Vec<f64> = thrust
            .as_array()
            .iter()
            .map(|&f| self.inner.raw_duty(f))
            .collect();
        PyArray1::from_vec(py, out)
    }

    /// Duties of thrusts, clamped to [min_duty, max_duty].
    fn duty<'py>(
        &self,
        py: Python<'py>,
        thrust: PyReadonlyArray1<'py, f64>,
    ) -> Bound<'py, PyArray1<f64>> {
        let out: Vec<f64> = thrust
            .as_array()
            .iter()
            .map(|&f| self.inner.duty(f))
            .collect();
        PyArray1::from_vec(py, out)
    }

    /// Voltage factor in use.
    #[getter]
    fn voltage_factor(&self) -> f64 {
        self.inner.voltage_factor()
    }

    /// Index of the reference curve in use.
    #[getter]
    fn reference_index(&self) -> usize {
        self.inner.reference_index()
    }

    /// Lowest duty in use.
    #[getter]
    fn min_duty(&self) -> f64 {
        self.inner.min_duty()
    }

    /// Highest duty.
    #[getter]
    fn max_duty(&self) -> f64 {
        self.inner.max_duty()
    }

    /// `max_thrust / v_factor` of the reference in use, N.
    #[getter]
    fn thrust_limit(&self) -> f64 {
        self.inner.thrust_limit()
    }

    /// Voltages rejected: non-finite or non-positive, or outside the guard's window.
    #[getter]
    fn rejected_voltages(&self) -> u64 {
        self.inner.rejected_voltages()
    }

    /// The plausible voltage window (low, high), V; None with the guard off.
    #[getter]
    fn voltage_window(&self) -> Option<(f64, f64)> {
        self.inner.voltage_window()
    }

    /// The last voltage that passed the guard, V (at first the first reference's).
    #[getter]
    fn last_good_voltage(&self) -> f64 {
        self.inner.last_good_voltage()
    }
}

fn map_u16<'py>(
    py: Python<'py>,
    duty: &PyReadonlyArray1<'py, f64>,
    f: fn(f64) -> u16,
) -> Bound<'py, PyArray1<u16>> {
    PyArray1::from_vec(py, duty.as_array().iter().map(|&d| f(d)).collect())
}

/// `motor_pwms` values: `uint16(duty * 2000)`.
#[pyfunction]
fn duty_to_pwm_report<'py>(
    py: Python<'py>,
    duty: PyReadonlyArray1<'py, f64>,
) -> Bound<'py, PyArray1<u16>> {
    map_u16(py, &duty, duty_to_report)
}

/// Neuron CAN motor values: `uint16(duty * 2000 - 1000)` clamped to 0..=1000.
#[pyfunction]
fn duty_to_can<'py>(
    py: Python<'py>,
    duty: PyReadonlyArray1<'py, f64>,
) -> Bound<'py, PyArray1<u16>> {
    map_u16(py, &duty, duty_to_can_value)
}

/// DShot throttles: `(duty - 0.5)/0.5 * 1999 + 48`, truncated, clamped to 48..=2047.
#[pyfunction(name = "duty_to_dshot")]
fn py_duty_to_dshot<'py>(
    py: Python<'py>,
    duty: PyReadonlyArray1<'py, f64>,
) -> Bound<'py, PyArray1<u16>> {
    map_u16(py, &duty, duty_to_dshot)
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyPwmConverter>()?;
    m.add_function(wrap_pyfunction!(duty_to_pwm_report, m)?)?;
    m.add_function(wrap_pyfunction!(duty_to_can, m)?)?;
    m.add_function(wrap_pyfunction!(py_duty_to_dshot, m)?)?;
    Ok(())
}
