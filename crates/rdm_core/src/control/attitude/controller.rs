//! The Spinal attitude controller and its arming / fail-safe state machine
//! (`jsk-wire-protocols.md` sec. 3.4-3.7; `attitude_control.cpp` `update`, `pwmConversion`).
//!
//! Per step: frames with the desired coordinate, roll/pitch errors and integral, per-rotor
//! P-I-D thrust terms with the gyro-moment compensation of eq. (29), yaw spreading, the
//! saturation factors alpha/beta, and the thrust -> duty conversion ([`crate::pwm`]).
//! Everything is driven by the caller's timestamp; nothing reads a clock.

use nalgebra::{Matrix3, Vector3};

use super::events::{CommandError, EventList, FlightConfigCmd, SpinalEvent};
use super::wire::{from_wire, inertia_from_wire, inertia_matrix, RollPitchYawTermWire};
use crate::control::gains::GainSet;
use crate::estimate::{euler_zyx, rotation_from_euler};
use crate::pwm::{duty_to_report, PwmConverter, PwmInfo, IDLE_DUTY};
use crate::N_ROTORS;

/// `spinal/UavInfo.DRAGON`: dual rotors per link, so thrust is halved before conversion.
pub const UAV_MODEL_DRAGON: u8 = 32;
/// Firmware force-landing decrement per 1 ms step (`FORCE_LANDING_INTEGRAL`), N.
pub const FIRMWARE_FORCE_LANDING_STEP: f64 = 0.0025;

/// Integrator anti-windup (the firmware has none).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum AntiWindup {
    /// Firmware-exact: `e_i += e dt` without any bound.
    Off,
    /// `|e_i| <= limit` per axis, and no integration that would grow `|e_i|` while the
    /// previous step saturated (alpha < 0, or a rotor's duty clamped at min/max).
    ClampAndConditional {
        /// Bound of each roll/pitch error integral, rad s.
        limit: f64,
    },
}

/// Parameters of [`AttitudeController`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AttitudeControlConfig {
    /// Step rate, Hz (integration `dt = 1/rate_hz`; firmware 1000).
    pub rate_hz: f64,
    /// Integrator anti-windup; default on with a 1.0 rad s bound.
    pub anti_windup: AntiWindup,
    /// FourAxisCommand timeout, s (firmware `FLIGHT_COMMAND_TIMEOUT` 500 ms).
    pub command_timeout_s: f64,
    /// Roll/pitch bound, rad (firmware `MAX_TILT_ANGLE` 1.0).
    pub max_tilt_rad: f64,
    /// Force-landing decrease of the average base thrust, N/s (firmware 0.0025 N per 1 ms
    /// step = 2.5 N/s; applied per step as `rate * dt`).
    pub force_landing_rate: f64,
}

impl Default for AttitudeControlConfig {
    fn default() -> Self {
        Self {
            rate_hz: 200.0,
            anti_windup: AntiWindup::ClampAndConditional { limit: 1.0 },
            command_timeout_s: 0.5,
            max_tilt_rad: 1.0,
            force_landing_rate: FIRMWARE_FORCE_LANDING_STEP * 1000.0,
        }
    }
}

impl AttitudeControlConfig {
    /// Firmware-exact behaviour at `rate_hz` (no anti-windup).
    pub fn firmware(rate_hz: f64) -> Self {
        Self {
            rate_hz,
            anti_windup: AntiWindup::Off,
            ..Self::default()
        }
    }

    /// Checks every field; names the field at fault.
    pub fn validate(&self) -> Result<(), &'static str> {
        if !(self.rate_hz.is_finite() && self.rate_hz > 0.0 && self.rate_hz <= 10_000.0) {
            return Err("rate_hz");
        }
        if let AntiWindup::ClampAndConditional { limit } = self.anti_windup {
            if !(limit.is_finite() && limit >= 0.0) {
                return Err("anti_windup.limit");
            }
        }
        for (value, name) in [
            (self.command_timeout_s, "command_timeout_s"),
            (self.max_tilt_rad, "max_tilt_rad"),
            (self.force_landing_rate, "force_landing_rate"),
        ] {
            if !(value.is_finite() && value >= 0.0) {
                return Err(name);
            }
        }
        Ok(())
    }
}

/// Flight state reported by a step.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ControlStatus {
    /// Not armed: motors idle (duty 0.5).
    Disarmed,
    /// Armed and controlling.
    Armed,
    /// Armed, force landing.
    ForceLanding,
    /// A NaN/inf input (time, rotation or rate): no update, outputs held.
    InvalidInput,
}

/// Result of one controller step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AttitudeOutput {
    /// Flight state.
    pub status: ControlStatus,
    /// Target thrust per rotor, N (`f_i = rp_i + (1+alpha) base_i + (1+beta) yaw_i`).
    pub thrust: [f64; N_ROTORS],
    /// Duty per rotor (0.5 = stopped), clamped to `[min_duty, max_duty]` while armed.
    pub duty: [f64; N_ROTORS],
    /// `motor_pwms` values (duty x 2000, us).
    pub pwm_report: [u16; N_ROTORS],
    /// Base-thrust saturation factor alpha (<= 0).
    pub alpha: f64,
    /// Yaw saturation factor beta in [-1, 0].
    pub beta: f64,
    /// Roll, pitch, yaw in the desired coordinate frame, rad.
    pub euler: [f64; 3],
    /// Roll and pitch error integrals, rad s.
    pub error_integral: [f64; 2],
    /// Acknowledgements and fail-safe events since the previous step.
    pub events: EventList,
}

/// Per-rotor gains, one `[roll, pitch, yaw]` row per rotor.
pub type RotorAxisGains = [[f64; 3]; N_ROTORS];

/// Counters of rejected or ignored messages and fail-safe triggers.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ControlCounters {
    /// Messages rejected for a wrong array length.
    pub wrong_length: u64,
    /// Messages rejected for NaN/inf values.
    pub non_finite: u64,
    /// Messages ignored for another reason (not armed, not activated, below force-landing
    /// thrust, unknown motor number or command).
    pub ignored: u64,
    /// Steps skipped for NaN/inf inputs.
    pub invalid_steps: u64,
    /// Fail-safe force landings started (timeout, tilt or commanded tilt).
    pub failsafes: u64,
}

/// The Spinal attitude controller with its flight state machine.
#[derive(Clone, Debug)]
pub struct AttitudeController {
    config: AttitudeControlConfig,
    dt: f64,
    // Vehicle description.
    motor_number: usize,
    uav_model: i16,
    rotor_divider: f64,
    pwm: Option<PwmConverter>,
    // Flags.
    start_control: bool,
    force_landing: bool,
    att_control: bool,
    integrate: bool,
    failsafe_armed: bool,
    last_command_s: f64,
    // Gains: per rotor, axes roll, pitch, yaw (yaw uses d only).
    p_gain: [[f64; 3]; N_ROTORS],
    i_gain: [[f64; 3]; N_ROTORS],
    d_gain: [[f64; 3]; N_ROTORS],
    torque_gain: [[f64; 3]; 3],
    torque_allocation_inv: [[f64; 3]; N_ROTORS],
    max_yaw_index: Option<usize>,
    pinv: [[f64; 3]; N_ROTORS],
    inertia: Matrix3<f64>,
    offset_rot: Matrix3<f64>,
    // Command and control state.
    target_angle: [f64; 2],
    error_i: [f64; 2],
    base_thrust: [f64; N_ROTORS],
    extra_yaw: [f64; N_ROTORS],
    rp_term: [f64; N_ROTORS],
    yaw_term: [f64; N_ROTORS],
    thrust: [f64; N_ROTORS],
    duty: [f64; N_ROTORS],
    alpha: f64,
    beta: f64,
    euler: [f64; 3],
    saturated: bool,
    events: EventList,
    counters: ControlCounters,
}

impl AttitudeController {
    /// A controller with nothing configured: motor number 0, no PWM info, disarmed.
    pub fn new(config: AttitudeControlConfig) -> Result<Self, &'static str> {
        config.validate()?;
        Ok(Self {
            dt: 1.0 / config.rate_hz,
            config,
            motor_number: 0,
            uav_model: -1,
            rotor_divider: 1.0,
            pwm: None,
            start_control: false,
            force_landing: false,
            att_control: true,
            integrate: false,
            failsafe_armed: false,
            last_command_s: 0.0,
            p_gain: [[0.0; 3]; N_ROTORS],
            i_gain: [[0.0; 3]; N_ROTORS],
            d_gain: [[0.0; 3]; N_ROTORS],
            torque_gain: [[0.0; 3]; 3],
            torque_allocation_inv: [[0.0; 3]; N_ROTORS],
            max_yaw_index: None,
            pinv: [[0.0; 3]; N_ROTORS],
            inertia: Matrix3::zeros(),
            offset_rot: Matrix3::identity(),
            target_angle: [0.0; 2],
            error_i: [0.0; 2],
            base_thrust: [0.0; N_ROTORS],
            extra_yaw: [0.0; N_ROTORS],
            rp_term: [0.0; N_ROTORS],
            yaw_term: [0.0; N_ROTORS],
            thrust: [0.0; N_ROTORS],
            duty: [IDLE_DUTY; N_ROTORS],
            alpha: 0.0,
            beta: 0.0,
            euler: [0.0; 3],
            saturated: false,
            events: EventList::default(),
            counters: ControlCounters::default(),
        })
    }

    // ----- read-only state -----

    /// The configuration in use.
    pub fn config(&self) -> &AttitudeControlConfig {
        &self.config
    }
    /// Motor number (0 until `uav_info`).
    pub fn motor_number(&self) -> usize {
        self.motor_number
    }
    /// Whether control is started (armed).
    pub fn armed(&self) -> bool {
        self.start_control
    }
    /// Whether force landing is active.
    pub fn force_landing(&self) -> bool {
        self.force_landing
    }
    /// Whether the roll/pitch integrator runs.
    pub fn integrating(&self) -> bool {
        self.integrate
    }
    /// Current base thrust per rotor, N (ramps down during force landing).
    pub fn base_thrust(&self) -> [f64; N_ROTORS] {
        self.base_thrust
    }
    /// Roll/pitch error integrals, rad s.
    pub fn error_integral(&self) -> [f64; 2] {
        self.error_i
    }
    /// Roll/pitch targets, rad.
    pub fn target_angles(&self) -> [f64; 2] {
        self.target_angle
    }
    /// Rotor with the largest positive yaw d gain.
    pub fn max_yaw_index(&self) -> Option<usize> {
        self.max_yaw_index
    }
    /// The PWM converter, once `motor_info` arrived.
    pub fn pwm(&self) -> Option<&PwmConverter> {
        self.pwm.as_ref()
    }
    /// Counters since construction.
    pub fn counters(&self) -> &ControlCounters {
        &self.counters
    }
    /// The per-rotor thrust gains Spinal applies: (P, I, D) for roll, pitch, yaw.
    pub fn thrust_gains(&self) -> (RotorAxisGains, RotorAxisGains, RotorAxisGains) {
        (self.p_gain, self.i_gain, self.d_gain)
    }

    /// ARM_ON preconditions (`activated()`).
    pub fn activated(&self) -> bool {
        let duty_range_ok = self
            .pwm
            .as_ref()
            .is_some_and(|p| p.max_duty() > p.min_duty());
        self.motor_number > 0 && self.uav_model >= 0 && duty_range_ok
    }

    fn reject(&mut self, error: CommandError) -> CommandError {
        match error {
            CommandError::WrongLength { .. } => {
                self.counters.wrong_length += 1;
                self.events.push(SpinalEvent::Rejected(error));
            }
            CommandError::NonFinite(_) => self.counters.non_finite += 1,
            _ => self.counters.ignored += 1,
        }
        error
    }

    fn check_length(&mut self, field: &'static str, got: usize) -> Result<(), CommandError> {
        if self.motor_number == 0 {
            return Err(self.reject(CommandError::MotorNumberUnknown));
        }
        if got != self.motor_number {
            return Err(self.reject(CommandError::WrongLength {
                field,
                expected: self.motor_number,
                got,
            }));
        }
        Ok(())
    }

    fn enter_force_landing(&mut self, reason: SpinalEvent) {
        if !self.force_landing {
            self.force_landing = true;
            self.counters.failsafes += 1;
            self.events.push(reason);
            self.events
                .push(SpinalEvent::Ack(FlightConfigCmd::ForceLanding));
        }
    }

    // ----- messages -----

    /// `uav_info`: motor number and model. As the firmware: a motor number different from
    /// an already known one sets it to 0 (blocks arming); DRAGON sets the rotor divider 2.
    pub fn set_uav_info(&mut self, motor_num: u8, uav_model: u8) -> Result<(), CommandError> {
        let motors = usize::from(motor_num);
        if motors > N_ROTORS {
            return Err(self.reject(CommandError::TooManyMotors(motors)));
        }
        if self.motor_number > 0 {
            if self.motor_number != motors {
                self.motor_number = 0;
            }
        } else {
            self.motor_number = motors;
        }
        // The firmware stores the byte in an int8.
        self.uav_model = i16::from(uav_model as i8);
        if uav_model == UAV_MODEL_DRAGON {
            self.rotor_divider = 2.0;
        }
        if let Some(pwm) = self.pwm.as_mut() {
            pwm.set_rotor_divider(self.rotor_divider);
        }
        Ok(())
    }

    /// `motor_info` (`PwmInfo`): thrust curves and duty limits.
    pub fn set_pwm_info(&mut self, info: PwmInfo) -> Result<(), CommandError> {
        match PwmConverter::new(info) {
            Ok(mut converter) => {
                converter.set_rotor_divider(self.rotor_divider);
                self.pwm = Some(converter);
                Ok(())
            }
            Err(e) => Err(self.reject(CommandError::InvalidPwmInfo(e))),
        }
    }

    /// `flight_config_cmd`.
    pub fn flight_config(&mut self, cmd: u8, now_s: f64) -> Result<(), CommandError> {
        let Some(command) = FlightConfigCmd::from_wire(cmd) else {
            return Err(self.reject(CommandError::UnknownFlightConfig(cmd)));
        };
        match command {
            FlightConfigCmd::ArmOn => {
                if !self.activated() {
                    return Err(self.reject(CommandError::NotActivated));
                }
                self.force_landing = false;
                self.start_control = true;
                self.events.push(SpinalEvent::Ack(command));
            }
            FlightConfigCmd::ArmOff => {
                self.start_control = false;
                self.reset(now_s);
                self.events.push(SpinalEvent::Ack(command));
            }
            FlightConfigCmd::ForceLanding => {
                self.force_landing = true;
                self.events.push(SpinalEvent::Ack(command));
            }
            FlightConfigCmd::IntegrationControlOn => self.integrate = true,
            FlightConfigCmd::IntegrationControlOff => self.integrate = false,
        }
        Ok(())
    }

    /// `set_attitude_control`: false skips the control computation (PWM output still runs).
    pub fn set_attitude_control(&mut self, enabled: bool) {
        self.att_control = enabled;
    }

    /// `desire_coordinate`: the control frame's roll, pitch, yaw.
    pub fn set_desire_coordinate(
        &mut self,
        roll: f64,
        pitch: f64,
        yaw: f64,
    ) -> Result<(), CommandError> {
        if !(roll.is_finite() && pitch.is_finite() && yaw.is_finite()) {
            return Err(self.reject(CommandError::NonFinite("desire_coordinate")));
        }
        self.offset_rot = rotation_from_euler(roll, pitch, yaw);
        Ok(())
    }

    /// `four_axes/command`: roll/pitch targets, the yaw term for the max-yaw-gain rotor, and
    /// the base thrust per rotor.
    pub fn four_axis_command(
        &mut self,
        angles: [f64; 3],
        base_thrust: &[f64],
        now_s: f64,
    ) -> Result<(), CommandError> {
        if !self.start_control {
            return Err(self.reject(CommandError::NotArmed));
        }
        if !(angles.iter().all(|a| a.is_finite())
            && base_thrust.iter().all(|f| f.is_finite())
            && now_s.is_finite())
        {
            return Err(self.reject(CommandError::NonFinite("four_axes/command")));
        }
        let tilt = self.config.max_tilt_rad;
        if angles[0].abs() > tilt || angles[1].abs() > tilt {
            self.enter_force_landing(SpinalEvent::FailsafeCommandTilt);
        }
        self.check_length("base_thrust", base_thrust.len())?;
        let n = self.motor_number;
        if self.force_landing {
            let average = base_thrust.iter().sum::<f64>() / n as f64;
            if average
                < self
                    .pwm
                    .as_ref()
                    .map_or(0.0, |p| p.info().force_landing_thrust)
            {
                return Err(self.reject(CommandError::BelowForceLandingThrust));
            }
        }
        self.failsafe_armed = true;
        self.last_command_s = now_s;
        self.target_angle = [angles[0], angles[1]];
        for (i, &thrust) in base_thrust.iter().enumerate().take(N_ROTORS) {
            self.base_thrust[i] = thrust;
            if let Some(imax) = self.max_yaw_index {
                self.extra_yaw[i] = angles[2] * self.d_gain[i][2] / self.d_gain[imax][2];
            }
        }
        Ok(())
    }

    /// `rpy/gain` from a [`GainSet`]: roll P/I/D, pitch P/I/D and yaw D of the first
    /// `motor_number` rotors (yaw P/I and z are applied on the PC).
    pub fn set_gains(&mut self, gains: &GainSet) -> Result<(), CommandError> {
        if self.motor_number == 0 {
            return Err(self.reject(CommandError::MotorNumberUnknown));
        }
        let finite = gains.iter().take(self.motor_number).all(|g| {
            [
                g.roll.p, g.roll.i, g.roll.d, g.pitch.p, g.pitch.i, g.pitch.d, g.yaw.d,
            ]
            .iter()
            .all(|v| v.is_finite())
        });
        if !finite {
            return Err(self.reject(CommandError::NonFinite("gains")));
        }
        for (i, g) in gains.iter().enumerate().take(self.motor_number) {
            self.p_gain[i] = [g.roll.p, g.pitch.p, 0.0];
            self.i_gain[i] = [g.roll.i, g.pitch.i, 0.0];
            self.d_gain[i] = [g.roll.d, g.pitch.d, g.yaw.d];
        }
        self.update_max_yaw_index();
        Ok(())
    }

    /// `rpy/gain` in wire form: `motor_number` per-rotor terms, or exactly one term of body
    /// torque gains mapped through `torque_allocation_matrix_inv` (`thrustGainMapping`).
    pub fn set_gains_wire(&mut self, terms: &[RollPitchYawTermWire]) -> Result<(), CommandError> {
        if self.motor_number == 0 {
            return Err(self.reject(CommandError::MotorNumberUnknown));
        }
        if terms.len() == 1 && self.motor_number != 1 {
            let t = terms[0];
            self.torque_gain = [
                [from_wire(t.roll_p), from_wire(t.pitch_p), 0.0],
                [from_wire(t.roll_i), from_wire(t.pitch_i), 0.0],
                [
                    from_wire(t.roll_d),
                    from_wire(t.pitch_d),
                    from_wire(t.yaw_d),
                ],
            ];
            self.thrust_gain_mapping();
        } else {
            self.check_length("rpy/gain.motors", terms.len())?;
            for (i, t) in terms.iter().enumerate().take(N_ROTORS) {
                self.p_gain[i] = [from_wire(t.roll_p), from_wire(t.pitch_p), 0.0];
                self.i_gain[i] = [from_wire(t.roll_i), from_wire(t.pitch_i), 0.0];
                self.d_gain[i] = [
                    from_wire(t.roll_d),
                    from_wire(t.pitch_d),
                    from_wire(t.yaw_d),
                ];
            }
        }
        self.update_max_yaw_index();
        Ok(())
    }

    /// `torque_allocation_matrix_inv` in wire form (one row per rotor, x 1000).
    pub fn set_torque_allocation_inv_wire(
        &mut self,
        rows: &[[i16; 3]],
    ) -> Result<(), CommandError> {
        self.check_length("torque_allocation_matrix_inv.rows", rows.len())?;
        for (dst, row) in self.torque_allocation_inv.iter_mut().zip(rows.iter()) {
            *dst = row.map(from_wire);
        }
        self.thrust_gain_mapping();
        self.update_max_yaw_index();
        Ok(())
    }

    /// `p_matrix_pseudo_inverse_inertia` in physical units: rows (r, p, y) of the allocation
    /// pseudo-inverse per rotor and the inertia (xx, yy, zz, xy, yz, xz), kg m^2.
    pub fn set_pinv_inertia(
        &mut self,
        pinv: &[[f64; 3]],
        inertia: [f64; 6],
    ) -> Result<(), CommandError> {
        self.check_length("p_matrix_pseudo_inverse_inertia.pseudo_inverse", pinv.len())?;
        if pinv
            .iter()
            .flatten()
            .chain(inertia.iter())
            .any(|v| !v.is_finite())
        {
            return Err(self.reject(CommandError::NonFinite("p_matrix_pseudo_inverse_inertia")));
        }
        for (dst, row) in self.pinv.iter_mut().zip(pinv.iter()) {
            *dst = *row;
        }
        self.inertia = inertia_matrix(&inertia);
        Ok(())
    }

    /// `p_matrix_pseudo_inverse_inertia` in wire form (x 1000).
    pub fn set_pinv_inertia_wire(
        &mut self,
        pinv: &[[i16; 3]],
        inertia: [i16; 6],
    ) -> Result<(), CommandError> {
        self.check_length("p_matrix_pseudo_inverse_inertia.pseudo_inverse", pinv.len())?;
        for (dst, row) in self.pinv.iter_mut().zip(pinv.iter()) {
            *dst = row.map(from_wire);
        }
        self.inertia = inertia_from_wire(&inertia);
        Ok(())
    }

    fn thrust_gain_mapping(&mut self) {
        for i in 0..self.motor_number.min(N_ROTORS) {
            let t = self.torque_allocation_inv[i];
            for (axis, &t_axis) in t.iter().enumerate() {
                self.p_gain[i][axis] = t_axis * self.torque_gain[0][axis];
                self.i_gain[i][axis] = t_axis * self.torque_gain[1][axis];
                self.d_gain[i][axis] = t_axis * self.torque_gain[2][axis];
            }
        }
    }

    fn update_max_yaw_index(&mut self) {
        let mut best = 0.0;
        self.max_yaw_index = None;
        for i in 0..self.motor_number.min(N_ROTORS) {
            if self.d_gain[i][2] > best {
                best = self.d_gain[i][2];
                self.max_yaw_index = Some(i);
            }
        }
    }

    /// Firmware `reset()` (on ARM_OFF): gains, integrals, terms and the fail-safe timer
    /// cleared, targets zero, every duty to idle. Vehicle description and PWM info stay.
    fn reset(&mut self, now_s: f64) {
        self.thrust = [0.0; N_ROTORS];
        self.duty = [IDLE_DUTY; N_ROTORS];
        self.base_thrust = [0.0; N_ROTORS];
        self.rp_term = [0.0; N_ROTORS];
        self.yaw_term = [0.0; N_ROTORS];
        self.extra_yaw = [0.0; N_ROTORS];
        self.p_gain = [[0.0; 3]; N_ROTORS];
        self.i_gain = [[0.0; 3]; N_ROTORS];
        self.d_gain = [[0.0; 3]; N_ROTORS];
        self.torque_allocation_inv = [[0.0; 3]; N_ROTORS];
        self.torque_gain = [[0.0; 3]; 3];
        self.target_angle = [0.0; 2];
        self.error_i = [0.0; 2];
        self.max_yaw_index = None;
        self.integrate = false;
        self.failsafe_armed = false;
        self.saturated = false;
        if now_s.is_finite() {
            self.last_command_s = now_s;
        }
    }

    // ----- the step -----

    /// One control step at time `now_s` with the estimated body attitude `rotation`
    /// (body -> world), the filtered body rate `gyro` and the battery voltage.
    /// Allocation-free; never panics.
    pub fn step(
        &mut self,
        now_s: f64,
        rotation: &Matrix3<f64>,
        gyro: &Vector3<f64>,
        voltage: f64,
    ) -> AttitudeOutput {
        let inputs_finite = now_s.is_finite()
            && rotation.iter().all(|v| v.is_finite())
            && gyro.iter().all(|v| v.is_finite());
        if !inputs_finite {
            self.counters.invalid_steps += 1;
            return self.output(ControlStatus::InvalidInput);
        }
        if self.start_control && self.att_control {
            self.control_law(now_s, rotation, gyro);
        }
        self.pwm_conversion(now_s, voltage);
        let status = if !self.start_control {
            ControlStatus::Disarmed
        } else if self.force_landing {
            ControlStatus::ForceLanding
        } else {
            ControlStatus::Armed
        };
        self.output(status)
    }

    fn output(&mut self, status: ControlStatus) -> AttitudeOutput {
        let events = self.events;
        self.events.clear();
        AttitudeOutput {
            status,
            thrust: self.thrust,
            duty: self.duty,
            pwm_report: self.duty.map(duty_to_report),
            alpha: self.alpha,
            beta: self.beta,
            euler: self.euler,
            error_integral: self.error_i,
            events,
        }
    }

    fn control_law(&mut self, now_s: f64, rotation: &Matrix3<f64>, gyro: &Vector3<f64>) {
        // Fail-safe 1: command timeout (armed only after the first accepted command).
        if self.failsafe_armed
            && !self.force_landing
            && now_s - self.last_command_s > self.config.command_timeout_s
        {
            self.enter_force_landing(SpinalEvent::FailsafeCommandTimeout);
        }

        let rot = rotation * self.offset_rot.transpose();
        let vel = self.offset_rot * gyro;
        self.euler = euler_zyx(&rot);

        // Fail-safe 2: estimated tilt.
        let tilt = self.config.max_tilt_rad;
        if !self.force_landing && (self.euler[0].abs() > tilt || self.euler[1].abs() > tilt) {
            self.enter_force_landing(SpinalEvent::FailsafeTilt);
            self.error_i = [0.0; 2];
        }
        if self.force_landing {
            self.target_angle = [0.0; 2];
            self.extra_yaw = [0.0; N_ROTORS];
        }

        // Roll/pitch errors and their integral.
        let error = [
            self.target_angle[0] - self.euler[0],
            self.target_angle[1] - self.euler[1],
        ];
        if self.integrate {
            for (axis, &e) in error.iter().enumerate() {
                self.integrate_axis(axis, e);
            }
        }

        // Per-rotor P-I-D terms plus the gyro-moment compensation of eq. (29).
        let gyro_moment = vel.cross(&(self.inertia * vel));
        for i in 0..self.motor_number.min(N_ROTORS) {
            let mut rp = 0.0;
            for axis in 0..2 {
                rp += error[axis] * self.p_gain[i][axis]
                    + self.error_i[axis] * self.i_gain[i][axis]
                    - vel[axis] * self.d_gain[i][axis];
            }
            let pinv = self.pinv[i];
            rp += pinv[0] * gyro_moment.x + pinv[1] * gyro_moment.y + pinv[2] * gyro_moment.z;
            self.rp_term[i] = rp;
            self.yaw_term[i] = self.extra_yaw[i] - vel[2] * self.d_gain[i][2];
        }

        // Force-landing ramp: the average base thrust falls at force_landing_rate.
        if self.force_landing && self.motor_number > 0 {
            let n = self.motor_number.min(N_ROTORS);
            let average = self.base_thrust[..n].iter().sum::<f64>() / n as f64;
            let landing_thrust = self
                .pwm
                .as_ref()
                .map_or(0.0, |p| p.info().force_landing_thrust);
            if average > landing_thrust {
                let step = self.config.force_landing_rate * self.dt;
                for base in &mut self.base_thrust[..n] {
                    *base -= *base / average * step;
                }
            }
        }
    }

    fn integrate_axis(&mut self, axis: usize, error: f64) {
        let increment = error * self.dt;
        match self.config.anti_windup {
            AntiWindup::Off => self.error_i[axis] += increment,
            AntiWindup::ClampAndConditional { limit } => {
                let grows = self.error_i[axis] * increment > 0.0 || self.error_i[axis] == 0.0;
                if !(self.saturated && grows) {
                    self.error_i[axis] = (self.error_i[axis] + increment).clamp(-limit, limit);
                }
            }
        }
    }

    fn pwm_conversion(&mut self, now_s: f64, voltage: f64) {
        let Some(pwm) = self.pwm.as_mut() else {
            return;
        };
        pwm.update_voltage(voltage, now_s);
        let pwm = &*pwm;
        let n = self.motor_number.min(N_ROTORS);
        let rd = self.rotor_divider;
        let limit = pwm.thrust_limit();

        // Saturation level 2: z control (base + roll/pitch) beyond the thrust limit.
        let mut alpha = 0.0;
        let mut beta = 0.0;
        let mut max_thrust = 0.0;
        let mut max_index = 0;
        for i in 0..n {
            let thrust = self.base_thrust[i] + self.rp_term[i];
            if max_thrust < thrust {
                max_thrust = thrust;
                max_index = i;
            }
        }
        if self.start_control {
            let residual = limit - max_thrust / rd;
            if residual < 0.0 && self.base_thrust[max_index] > 0.0 {
                alpha = residual / (self.base_thrust[max_index] / rd);
                beta = -1.0;
            } else if self.max_yaw_index.is_some() && self.base_thrust[0] != 0.0 {
                // Saturation level 1: yaw pushes a rotor past max or below min thrust.
                let mut max_thrust = 0.0;
                let mut min_thrust = 10_000.0;
                let (mut max_index, mut min_index) = (0, 0);
                for i in 0..n {
                    let thrust = self.base_thrust[i] + self.rp_term[i] + self.yaw_term[i];
                    if max_thrust < thrust {
                        max_thrust = thrust;
                        max_index = i;
                    }
                    if min_thrust > thrust {
                        min_thrust = thrust;
                        min_index = i;
                    }
                }
                let residual_max = limit - max_thrust / rd;
                let residual_min = min_thrust / rd - pwm.info().min_thrust;
                let (residual, index) = if residual_min < residual_max {
                    (residual_min, min_index)
                } else {
                    (residual_max, max_index)
                };
                if residual < 0.0 {
                    beta = residual / (self.yaw_term[index].abs() / rd);
                }
                // NaN (0/0) cannot occur: residual < 0 here; -inf clamps to -1.
                beta = beta.clamp(-1.0, 0.0);
            } else {
                beta = -1.0;
            }
        }
        self.alpha = alpha;
        self.beta = beta;

        let mut saturated = alpha < 0.0;
        for i in 0..n {
            self.thrust[i] = self.rp_term[i]
                + (1.0 + alpha) * self.base_thrust[i]
                + (1.0 + beta) * self.yaw_term[i];
            if self.start_control {
                let raw = pwm.raw_duty(self.thrust[i]);
                let clamped = pwm.clamp_duty(raw);
                saturated |= raw != clamped;
                self.duty[i] = clamped;
            }
        }
        self.saturated = saturated && self.start_control;
    }
}
