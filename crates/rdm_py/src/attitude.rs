//! Bindings of `rdm_core::control::attitude`: the Spinal attitude controller with its
//! arming/fail-safe state machine, the combined `SpinalStep`, PWM conversion and the gain
//! wire form.

mod config;
mod pwm;
mod wire;

use config::{control_config, events_list, ControlOptions};

pub(crate) use wire::wire_term_rows;

use numpy::{
    PyArray1, PyArray2, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3, PyUntypedArrayMethods,
};
use pyo3::create_exception;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use rdm_core::control::attitude::{
    AttitudeController, AttitudeOutput, CommandError, ControlStatus, SpinalConfig, SpinalOutput,
    SpinalStep,
};
use rdm_core::estimate::ImuSample;

use crate::errors::RdmError;
use crate::estimate::{counters_dict, estimate_into_dict, estimator_config, status_name};

create_exception!(
    _rdm,
    CommandRejectedError,
    RdmError,
    "A message to the Spinal controller was rejected or ignored; the message names the field."
);

pub(crate) fn rejected(e: CommandError) -> PyErr {
    CommandRejectedError::new_err(e.to_string())
}

fn control_status_name(s: ControlStatus) -> &'static str {
    match s {
        ControlStatus::Disarmed => "disarmed",
        ControlStatus::Armed => "armed",
        ControlStatus::ForceLanding => "force_landing",
        ControlStatus::InvalidInput => "invalid_input",
    }
}

/// Output of one controller step. Arrays are built when read.
#[pyclass(module = "rdm._rdm", frozen)]
pub struct ControlOutput {
    inner: AttitudeOutput,
}

#[pymethods]
impl ControlOutput {
    /// "disarmed", "armed", "force_landing" or "invalid_input".
    #[getter]
    fn status(&self) -> &'static str {
        control_status_name(self.inner.status)
    }
    /// Target thrust per rotor, N.
    #[getter]
    fn thrust<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_slice(py, &self.inner.thrust[..self.inner.outputs])
    }
    /// Duty per rotor (0.5 = stopped).
    #[getter]
    fn duty<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_slice(py, &self.inner.duty[..self.inner.outputs])
    }
    /// `motor_pwms` values (duty x 2000).
    #[getter]
    fn pwm_report<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<u16>> {
        PyArray1::from_slice(py, &self.inner.pwm_report[..self.inner.outputs])
    }
    /// Base-thrust saturation factor alpha.
    #[getter]
    fn alpha(&self) -> f64 {
        self.inner.alpha
    }
    /// Yaw saturation factor beta.
    #[getter]
    fn beta(&self) -> f64 {
        self.inner.beta
    }
    /// Roll, pitch, yaw in the desired coordinate frame, rad.
    #[getter]
    fn euler<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_slice(py, &self.inner.euler)
    }
    /// Roll/pitch error integrals, rad s.
    #[getter]
    fn error_integral<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_slice(py, &self.inner.error_integral)
    }
    /// Events since the previous step: ("ack", cmd), ("failsafe_timeout", None),
    /// ("failsafe_tilt", None), ("failsafe_command_tilt", None), ("rejected", message),
    /// ("voltage_rejected", None), ("command_saturated", None), ("non_finite_output", None),
    /// ("alpha_bounded", None); ("events_dropped", n) last when some were lost.
    #[getter]
    fn events<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        events_list(py, &self.inner)
    }
}

/// Output of one `SpinalStep.step`: the controller output plus the estimate.
#[pyclass(module = "rdm._rdm", frozen)]
pub struct SpinalStepOutput {
    /// Read by the mirror's busy-ms helpers (`crate::spinal_mirror`).
    pub(crate) inner: SpinalOutput,
}

#[pymethods]
impl SpinalStepOutput {
    /// Estimator status name of this sample.
    #[getter]
    fn estimate_status(&self) -> &'static str {
        status_name(self.inner.estimate_status)
    }
    /// The controller output.
    #[getter]
    fn control(&self) -> ControlOutput {
        ControlOutput {
            inner: self.inner.control,
        }
    }
    /// Controller status name.
    #[getter]
    fn status(&self) -> &'static str {
        control_status_name(self.inner.control.status)
    }
    /// Duty per rotor.
    #[getter]
    fn duty<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_slice(py, &self.inner.control.duty[..self.inner.control.outputs])
    }
    /// Thrust per rotor, N.
    #[getter]
    fn thrust<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_slice(py, &self.inner.control.thrust[..self.inner.control.outputs])
    }
    /// Estimated roll, pitch, yaw (body, ZYX), rad.
    #[getter]
    fn euler<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_slice(py, &self.inner.estimate.euler)
    }
    /// Estimated quaternion x, y, z, w.
    #[getter]
    fn quaternion<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_slice(py, &self.inner.estimate.quaternion)
    }
    /// Filtered body rate, rad/s.
    #[getter]
    fn angular_velocity<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_slice(py, self.inner.estimate.angular_velocity.as_slice())
    }
    /// The estimate as a dict of arrays (rotation, quaternion, euler, angular_velocity).
    fn estimate<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        estimate_into_dict(py, &self.inner.estimate, &d)?;
        Ok(d)
    }
    /// Controller events (see `ControlOutput.events`).
    #[getter]
    fn events<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        events_list(py, &self.inner.control)
    }
}

fn three_rows<T: numpy::Element + Copy>(
    a: &PyReadonlyArray2<'_, T>,
    field: &str,
) -> PyResult<Vec<[T; 3]>> {
    if a.ndim() != 2 || a.shape()[1] != 3 {
        return Err(RdmError::new_err(format!("{field}: need shape (n, 3)")));
    }
    Ok(a.as_array()
        .rows()
        .into_iter()
        .map(|r| [r[0], r[1], r[2]])
        .collect())
}

/// Gives the message methods access to the controller of either class.
trait ControllerHost {
    fn ctrl(&mut self) -> &mut AttitudeController;
    fn ctrl_ref(&self) -> &AttitudeController;
}

/// The message and state methods shared by `AttitudeController` and `SpinalStep`, plus
/// the class-specific methods passed in.
macro_rules! controller_pymethods {
    ($ty:ty, { $($extra:tt)* }) => {
        #[pymethods]
        impl $ty {
            $($extra)*

            /// `uav_info`: motor number and model (DRAGON = 32 halves the thrust per rotor).
            fn set_uav_info(&mut self, motor_num: u8, uav_model: u8) -> PyResult<()> {
                self.ctrl().set_uav_info(motor_num, uav_model).map_err(rejected)
            }

            /// `motor_info`: rows (voltage, max_thrust, p0..p4); mode 0 SQRT, 1 POLY.
            #[pyo3(signature = (min_pwm, max_pwm, min_thrust, force_landing_thrust, mode, motor_info))]
            fn set_pwm_info(&mut self, min_pwm: f64, max_pwm: f64, min_thrust: f64,
                            force_landing_thrust: f64, mode: u8,
                            motor_info: PyReadonlyArray2<'_, f64>) -> PyResult<()> {
                let info = pwm::pwm_info(min_pwm, max_pwm, min_thrust, force_landing_thrust, mode, &motor_info)?;
                self.ctrl().set_pwm_info(info).map_err(rejected)
            }

            /// `motor_info` of the Hydrus quad example (SQRT, 25.2 V curve).
            fn set_pwm_info_hydrus_example(&mut self) -> PyResult<()> {
                self.ctrl().set_pwm_info(rdm_core::pwm::PwmInfo::hydrus_example()).map_err(rejected)
            }

            /// `flight_config_cmd` (0 ARM_ON, 1 ARM_OFF, 2 FORCE_LANDING, 160/161 integration).
            fn flight_config(&mut self, cmd: u8, now_s: f64) -> PyResult<()> {
                self.ctrl().flight_config(cmd, now_s).map_err(rejected)
            }

            /// `four_axes/command`: angles (roll, pitch, yaw term), base thrust per motor.
            fn four_axis_command(&mut self, angles: [f64; 3], base_thrust: PyReadonlyArray1<'_, f64>, now_s: f64) -> PyResult<()> {
                let base = base_thrust.as_slice().map_err(|_| RdmError::new_err("base_thrust: need a contiguous 1-D array"))?;
                self.ctrl().four_axis_command(angles, base, now_s).map_err(rejected)
            }

            /// `four_axis_command` with the base thrust as a list (no numpy array on the way).
            fn four_axis_command_list(&mut self, angles: [f64; 3], base_thrust: Vec<f64>, now_s: f64) -> PyResult<()> {
                self.ctrl().four_axis_command(angles, &base_thrust, now_s).map_err(rejected)
            }

            /// `rpy/gain` from a gain set of shape (motor_number, 4, 3).
            fn set_gains(&mut self, gains: PyReadonlyArray3<'_, f64>) -> PyResult<()> {
                let (set, _) = wire::gain_set(&gains)?;
                self.ctrl().set_gains(&set).map_err(rejected)
            }

            /// `rpy/gain` in wire form: int array (motor_number or 1, 7).
            fn set_gains_wire(&mut self, terms: PyReadonlyArray2<'_, i64>) -> PyResult<()> {
                let terms = wire::wire_terms(&terms)?;
                self.ctrl().set_gains_wire(&terms).map_err(rejected)
            }

            /// `set_gains_wire` from a list of rows of 7 ints (roll p/i/d, pitch p/i/d, yaw d):
            /// the same terms without a numpy array on the way.
            fn set_gains_wire_rows(&mut self, rows: Vec<[i64; 7]>) -> PyResult<()> {
                let terms = wire::wire_term_rows(&rows)?;
                self.ctrl().set_gains_wire(&terms).map_err(rejected)
            }

            /// `torque_allocation_matrix_inv` in wire form: int16 rows (motor_number, 3).
            fn set_torque_allocation_inv_wire(&mut self, rows: PyReadonlyArray2<'_, i16>) -> PyResult<()> {
                let rows = three_rows(&rows, "rows")?;
                self.ctrl().set_torque_allocation_inv_wire(&rows).map_err(rejected)
            }

            /// `p_matrix_pseudo_inverse_inertia`: pinv rows (motor_number, 3) and inertia
            /// (xx, yy, zz, xy, yz, xz), physical units.
            fn set_pinv_inertia(&mut self, pinv: PyReadonlyArray2<'_, f64>, inertia: [f64; 6]) -> PyResult<()> {
                let rows = three_rows(&pinv, "pinv")?;
                self.ctrl().set_pinv_inertia(&rows, inertia).map_err(rejected)
            }

            /// `p_matrix_pseudo_inverse_inertia` in wire form (int16 x 1000).
            fn set_pinv_inertia_wire(&mut self, pinv: PyReadonlyArray2<'_, i16>, inertia: [i16; 6]) -> PyResult<()> {
                let rows = three_rows(&pinv, "pinv")?;
                self.ctrl().set_pinv_inertia_wire(&rows, inertia).map_err(rejected)
            }

            /// `set_pinv_inertia_wire` from a list of int16 rows `(r, p, y)` (no numpy array).
            fn set_pinv_inertia_wire_rows(&mut self, pinv: Vec<[i16; 3]>, inertia: [i16; 6]) -> PyResult<()> {
                self.ctrl().set_pinv_inertia_wire(&pinv, inertia).map_err(rejected)
            }

            /// `desire_coordinate`: roll, pitch, yaw of the control frame.
            fn set_desire_coordinate(&mut self, roll: f64, pitch: f64, yaw: f64) -> PyResult<()> {
                self.ctrl().set_desire_coordinate(roll, pitch, yaw).map_err(rejected)
            }

            /// `set_attitude_control`.
            fn set_attitude_control(&mut self, enabled: bool) {
                self.ctrl().set_attitude_control(enabled);
            }

            /// Whether armed.
            #[getter]
            fn armed(&self) -> bool { self.ctrl_ref().armed() }
            /// Whether force landing.
            #[getter]
            fn force_landing(&self) -> bool { self.ctrl_ref().force_landing() }
            /// Whether the roll/pitch integrator runs.
            #[getter]
            fn integrating(&self) -> bool { self.ctrl_ref().integrating() }
            /// Motor number (0 until uav_info).
            #[getter]
            fn motor_number(&self) -> usize { self.ctrl_ref().motor_number() }
            /// Base thrust per rotor, N.
            #[getter]
            fn base_thrust<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
                PyArray1::from_slice(py, &self.ctrl_ref().base_thrust()[..self.ctrl_ref().config().motor_outputs])
            }
            /// Roll/pitch error integrals, rad s.
            #[getter]
            fn error_integral<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
                PyArray1::from_slice(py, &self.ctrl_ref().error_integral())
            }
            /// Roll/pitch targets, rad.
            #[getter]
            fn target_angles<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
                PyArray1::from_slice(py, &self.ctrl_ref().target_angles())
            }
            /// Rotor with the largest positive yaw d gain, or None.
            #[getter]
            fn max_yaw_index(&self) -> Option<usize> { self.ctrl_ref().max_yaw_index() }
            /// Per-rotor thrust gains Spinal applies, shape (3, motor_outputs * 3): P, I, D x
            /// rotor x axis (roll, pitch, yaw).
            #[getter]
            fn thrust_gains<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
                let (p, i, d) = self.ctrl_ref().thrust_gains();
                let n = self.ctrl_ref().config().motor_outputs;
                let rows: Vec<Vec<f64>> = [p, i, d].iter().map(|g| g[..n].iter().flatten().copied().collect()).collect();
                Ok(PyArray2::from_vec2(py, &rows)?)
            }
            /// (min_duty, max_duty, voltage_factor, reference_index), or None before motor_info.
            #[getter]
            fn pwm_state(&self) -> Option<(f64, f64, f64, usize)> {
                self.ctrl_ref().pwm().map(|p| (p.min_duty(), p.max_duty(), p.voltage_factor(), p.reference_index()))
            }
            /// The plausible battery voltage window (low, high), V; None before motor_info or
            /// with the voltage guard off.
            #[getter]
            fn voltage_window(&self) -> Option<(f64, f64)> {
                self.ctrl_ref().pwm().and_then(|p| p.voltage_window())
            }
            /// The battery voltage in use after the guard, V (None before motor_info).
            #[getter]
            fn last_good_voltage(&self) -> Option<f64> {
                self.ctrl_ref().pwm().map(|p| p.last_good_voltage())
            }
            /// Counters: wrong_length, non_finite, ignored, invalid_steps, failsafes,
            /// rejected_voltages, saturated_commands, non_finite_outputs, bounded_alphas.
            #[getter]
            fn counters<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
                let c = self.ctrl_ref().counters();
                let d = PyDict::new(py);
                d.set_item("wrong_length", c.wrong_length)?;
                d.set_item("non_finite", c.non_finite)?;
                d.set_item("ignored", c.ignored)?;
                d.set_item("invalid_steps", c.invalid_steps)?;
                d.set_item("failsafes", c.failsafes)?;
                d.set_item("rejected_voltages", c.rejected_voltages)?;
                d.set_item("saturated_commands", c.saturated_commands)?;
                d.set_item("non_finite_outputs", c.non_finite_outputs)?;
                d.set_item("bounded_alphas", c.bounded_alphas)?;
                Ok(d)
            }
        }
    };
}

/// The Spinal attitude controller and flight state machine (see docs/spinal.md).
#[pyclass(module = "rdm._rdm", name = "AttitudeController")]
pub struct PyAttitudeController {
    inner: AttitudeController,
}

impl ControllerHost for PyAttitudeController {
    fn ctrl(&mut self) -> &mut AttitudeController {
        &mut self.inner
    }
    fn ctrl_ref(&self) -> &AttitudeController {
        &self.inner
    }
}

controller_pymethods!(PyAttitudeController, {
    #[new]
    #[pyo3(signature = (rate_hz = 200.0, *, firmware_exact = false, anti_windup = None,
                        integral_limit = 1.0, command_timeout_s = 0.5, max_tilt_rad = 1.0,
                        force_landing_rate = 2.5, voltage_guard = None, battery_cells = 0,
                        cell_voltage_range = (rdm_core::pwm::CELL_MIN_V, rdm_core::pwm::CELL_MAX_V),
                        saturate_commands = None, bound_alpha = None, motor_outputs = 4))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        rate_hz: f64,
        firmware_exact: bool,
        anti_windup: Option<bool>,
        integral_limit: f64,
        command_timeout_s: f64,
        max_tilt_rad: f64,
        force_landing_rate: f64,
        voltage_guard: Option<bool>,
        battery_cells: u32,
        cell_voltage_range: (f64, f64),
        saturate_commands: Option<bool>,
        bound_alpha: Option<bool>,
        motor_outputs: usize,
    ) -> PyResult<Self> {
        let config = control_config(&ControlOptions {
            rate_hz,
            firmware_exact,
            anti_windup,
            integral_limit,
            command_timeout_s,
            max_tilt_rad,
            force_landing_rate,
            voltage_guard,
            battery_cells,
            cell_voltage_range,
            saturate_commands,
            bound_alpha,
            motor_outputs,
        })?;
        let inner = AttitudeController::new(config)
            .map_err(|f| RdmError::new_err(format!("{f}: out of range")))?;
        Ok(Self { inner })
    }

    /// One step: time (s), body attitude (3x3, body -> world), filtered body rate (3),
    /// battery voltage (V).
    fn step(
        &mut self,
        now_s: f64,
        rotation: PyReadonlyArray2<'_, f64>,
        gyro: [f64; 3],
        voltage: f64,
    ) -> PyResult<ControlOutput> {
        if rotation.shape() != [3, 3] {
            return Err(RdmError::new_err("rotation: need shape (3, 3)"));
        }
        let r = rotation.as_array();
        let m = nalgebra::Matrix3::from_fn(|i, j| r[[i, j]]);
        let out = self
            .inner
            .step(now_s, &m, &nalgebra::Vector3::from(gyro), voltage);
        Ok(ControlOutput { inner: out })
    }
});

/// The Spinal mirror's step: estimator + attitude controller + PWM conversion.
///
/// `SpinalStep(rate_hz=200.0, *, time_matched=False, firmware_exact=False, ...,
/// **estimator_overrides)`: the controller's keywords as `AttitudeController`'s, the
/// estimator's overrides as `AttitudeEstimator`'s; `firmware_exact=True` selects the
/// firmware-exact option of every guard of both.
#[pyclass(module = "rdm._rdm", name = "SpinalStep")]
pub struct PySpinalStep {
    inner: SpinalStep,
    /// Steps run (`step` and the kernel's `step_raw`): the mirror's `control_steps`.
    steps: u64,
}

impl PySpinalStep {
    /// The attitude controller the message methods change (`crate::spinal_commands`).
    pub(crate) fn controller_mut(&mut self) -> &mut AttitudeController {
        self.inner.controller_mut()
    }

    /// [`SpinalStep::step`] without the Python object (the lockstep kernel's control step,
    /// `crate::kernel::spinal`): the same call `step` makes.
    pub(crate) fn step_raw(&mut self, now_s: f64, imu: &ImuSample, voltage: f64) -> SpinalOutput {
        self.steps = self.steps.saturating_add(1);
        self.inner.step(now_s, imu, voltage)
    }

    /// The controller's motor number (the `motor_number` property).
    pub(crate) fn motor_count(&self) -> usize {
        self.inner.controller().motor_number()
    }
}

impl ControllerHost for PySpinalStep {
    fn ctrl(&mut self) -> &mut AttitudeController {
        self.inner.controller_mut()
    }
    fn ctrl_ref(&self) -> &AttitudeController {
        self.inner.controller()
    }
}

controller_pymethods!(PySpinalStep, {
    #[new]
    #[pyo3(signature = (rate_hz = 200.0, *, time_matched = false, firmware_exact = false,
                        anti_windup = None, integral_limit = 1.0, command_timeout_s = 0.5,
                        max_tilt_rad = 1.0, force_landing_rate = 2.5, voltage_guard = None,
                        battery_cells = 0,
                        cell_voltage_range = (rdm_core::pwm::CELL_MIN_V, rdm_core::pwm::CELL_MAX_V),
                        saturate_commands = None, bound_alpha = None, motor_outputs = 4, **estimator_overrides))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        rate_hz: f64,
        time_matched: bool,
        firmware_exact: bool,
        anti_windup: Option<bool>,
        integral_limit: f64,
        command_timeout_s: f64,
        max_tilt_rad: f64,
        force_landing_rate: f64,
        voltage_guard: Option<bool>,
        battery_cells: u32,
        cell_voltage_range: (f64, f64),
        saturate_commands: Option<bool>,
        bound_alpha: Option<bool>,
        motor_outputs: usize,
        estimator_overrides: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<Self> {
        let config = SpinalConfig {
            estimator: estimator_config(
                rate_hz,
                time_matched,
                firmware_exact,
                estimator_overrides,
            )?,
            control: control_config(&ControlOptions {
                rate_hz,
                firmware_exact,
                anti_windup,
                integral_limit,
                command_timeout_s,
                max_tilt_rad,
                force_landing_rate,
                voltage_guard,
                battery_cells,
                cell_voltage_range,
                saturate_commands,
                bound_alpha,
                motor_outputs,
            })?,
        };
        let inner =
            SpinalStep::new(config).map_err(|f| RdmError::new_err(format!("{f}: out of range")))?;
        Ok(Self { inner, steps: 0 })
    }

    /// Steps run since construction (`step`, and the lockstep kernel's steps).
    #[getter]
    fn steps(&self) -> u64 {
        self.steps
    }

    /// The estimator's counters (see `AttitudeEstimator.counters`).
    #[getter]
    fn estimator_counters<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        counters_dict(py, self.inner.estimator().counters())
    }

    /// One step: time (s), raw gyro (rad/s), acc (m/s^2), mag (uT), battery voltage (V).
    fn step(
        &mut self,
        now_s: f64,
        gyro: [f64; 3],
        acc: [f64; 3],
        mag: [f64; 3],
        voltage: f64,
    ) -> SpinalStepOutput {
        self.steps = self.steps.saturating_add(1);
        let out = self
            .inner
            .step(now_s, &ImuSample { gyro, acc, mag }, voltage);
        SpinalStepOutput { inner: out }
    }

    /// Restarts the estimator's gyro bias calibration.
    fn restart_gyro_calibration(&mut self) {
        self.inner.estimator_mut().restart_gyro_calibration();
    }

    /// The calibration in use as `imu_calib` GET_CALIB_DATA lays it out (12 floats): gyro
    /// bias (rad/s; zero until the start-up window ends), accelerometer bias (m/s^2, the
    /// flash's), magnetometer bias and scale.
    fn calibration_data(&self) -> [f64; 12] {
        let est = self.inner.estimator();
        let c = est.config();
        let g = est.gyro_bias();
        let mut out = [0.0; 12];
        out[..3].copy_from_slice(g.as_slice());
        out[3..6].copy_from_slice(&c.acc_bias);
        out[6..9].copy_from_slice(&c.mag_bias);
        out[9..].copy_from_slice(&c.mag_scale);
        out
    }
});

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add(
        "CommandRejectedError",
        m.py().get_type::<CommandRejectedError>(),
    )?;
    m.add("MAX_ROTORS", rdm_core::MAX_ROTORS)?;
    m.add_class::<PyAttitudeController>()?;
    m.add_class::<PySpinalStep>()?;
    m.add_class::<ControlOutput>()?;
    m.add_class::<SpinalStepOutput>()?;
    pwm::register(m)?;
    wire::register(m)?;
    Ok(())
}
