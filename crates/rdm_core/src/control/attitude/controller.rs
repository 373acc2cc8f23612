//! The Spinal attitude controller and its arming / fail-safe state machine
//! (`jsk-wire-protocols.md` sec. 3.4-3.7; `attitude_control.cpp` `update`, `pwmConversion`).
//!
//! Per step: frames with the desired coordinate, roll/pitch errors and integral, per-rotor
//! P-I-D thrust terms with the gyro-moment compensation of eq. (29), yaw spreading, the
//! saturation factors alpha/beta, and the thrust -> duty conversion ([`crate::pwm`]).
//! Everything is driven by the caller's timestamp; nothing reads a clock.
//!
//! Output guards in every configuration: a non-finite thrust on any rotor gives every rotor
//! `min_duty` (idle while disarmed) and thrust 0, counted (`non_finite_outputs`) and reported
//! (`SpinalEvent::NonFiniteOutput`); no duty exceeds `max_pwm`. The configurable guards
//! (voltage window, command saturation) are in [`AttitudeControlConfig`].

mod messages;

use nalgebra::{Matrix3, Vector3};

use super::config::{AntiWindup, AttitudeControlConfig};
use super::events::{CommandError, EventList, FlightConfigCmd, SpinalEvent};
use crate::estimate::euler_zyx;
use crate::pwm::{duty_to_report, PwmConverter, IDLE_DUTY};
use crate::MAX_ROTORS;

/// `spinal/UavInfo.DRAGON`: dual rotors per link, so thrust is halved before conversion.
pub const UAV_MODEL_DRAGON: u8 = 32;

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
    /// ESC outputs (`AttitudeControlConfig::motor_outputs`): the valid length of `thrust`,
    /// `duty` and `pwm_report`.
    pub outputs: usize,
    /// Target thrust per rotor, N (`f_i = rp_i + (1+alpha) base_i + (1+beta) yaw_i`).
    pub thrust: [f64; MAX_ROTORS],
    /// Duty per rotor (0.5 = stopped), clamped to `[min_duty, max_duty]` while armed.
    pub duty: [f64; MAX_ROTORS],
    /// `motor_pwms` values (duty x 2000, us).
    pub pwm_report: [u16; MAX_ROTORS],
    /// Base-thrust saturation factor alpha (in `[-1, 0]` with `bound_alpha`, else <= 0).
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
pub type RotorAxisGains = [[f64; 3]; MAX_ROTORS];

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
    /// Battery voltages rejected by the PWM converter (not finite and positive, or outside
    /// the voltage guard's window), summed over every `motor_info`.
    pub rejected_voltages: u64,
    /// FourAxisCommands with a base thrust or yaw term saturated (`saturate_commands`).
    pub saturated_commands: u64,
    /// Steps whose computed thrust was not finite (every rotor then got `min_duty`).
    pub non_finite_outputs: u64,
    /// Steps whose alpha fell below -1 and was bounded to -1 (`bound_alpha`).
    pub bounded_alphas: u64,
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
    p_gain: [[f64; 3]; MAX_ROTORS],
    i_gain: [[f64; 3]; MAX_ROTORS],
    d_gain: [[f64; 3]; MAX_ROTORS],
    torque_gain: [[f64; 3]; 3],
    torque_allocation_inv: [[f64; 3]; MAX_ROTORS],
    max_yaw_index: Option<usize>,
    pinv: [[f64; 3]; MAX_ROTORS],
    inertia: Matrix3<f64>,
    offset_rot: Matrix3<f64>,
    // Command and control state.
    target_angle: [f64; 2],
    error_i: [f64; 2],
    base_thrust: [f64; MAX_ROTORS],
    extra_yaw: [f64; MAX_ROTORS],
    rp_term: [f64; MAX_ROTORS],
    yaw_term: [f64; MAX_ROTORS],
    thrust: [f64; MAX_ROTORS],
    duty: [f64; MAX_ROTORS],
    alpha: f64,
    beta: f64,
    euler: [f64; 3],
    saturated: bool,
    // Guard states: whether the last voltage update, command and step tripped the guard
    // (an event is reported on the first of a run only).
    voltage_rejecting: bool,
    command_saturating: bool,
    output_non_finite: bool,
    alpha_bounding: bool,
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
            p_gain: [[0.0; 3]; MAX_ROTORS],
            i_gain: [[0.0; 3]; MAX_ROTORS],
            d_gain: [[0.0; 3]; MAX_ROTORS],
            torque_gain: [[0.0; 3]; 3],
            torque_allocation_inv: [[0.0; 3]; MAX_ROTORS],
            max_yaw_index: None,
            pinv: [[0.0; 3]; MAX_ROTORS],
            inertia: Matrix3::zeros(),
            offset_rot: Matrix3::identity(),
            target_angle: [0.0; 2],
            error_i: [0.0; 2],
            base_thrust: [0.0; MAX_ROTORS],
            extra_yaw: [0.0; MAX_ROTORS],
            rp_term: [0.0; MAX_ROTORS],
            yaw_term: [0.0; MAX_ROTORS],
            thrust: [0.0; MAX_ROTORS],
            duty: [IDLE_DUTY; MAX_ROTORS],
            alpha: 0.0,
            beta: 0.0,
            euler: [0.0; 3],
            saturated: false,
            voltage_rejecting: false,
            command_saturating: false,
            output_non_finite: false,
            alpha_bounding: false,
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
    pub fn base_thrust(&self) -> [f64; MAX_ROTORS] {
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
            outputs: self.config.motor_outputs,
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
            self.extra_yaw = [0.0; MAX_ROTORS];
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
        for i in 0..self.motor_number.min(MAX_ROTORS) {
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
            let n = self.motor_number.min(MAX_ROTORS);
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
        let rejected_before = pwm.rejected_voltages();
        let used = pwm.update_voltage(voltage, now_s);
        if pwm.rejected_voltages() > rejected_before {
            self.counters.rejected_voltages += pwm.rejected_voltages() - rejected_before;
            if !self.voltage_rejecting {
                self.events.push(SpinalEvent::VoltageRejected);
            }
            self.voltage_rejecting = true;
        } else if used {
            self.voltage_rejecting = false;
        }
        let pwm = &*pwm;
        let n = self.motor_number.min(MAX_ROTORS);
        let rd = self.rotor_divider;
        let limit = pwm.thrust_limit();

        // Saturation level 2: z control (base + roll/pitch) beyond the thrust limit.
        let mut alpha = 0.0;
        let mut beta = 0.0;
        let mut alpha_bounded = false;
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
                // Rule: alpha in [-1, 0]. Below -1, (1 + alpha) < 0 reverses every base
                // thrust; -1 removes the base thrust and leaves the roll/pitch terms, whose
                // duties the clamp below keeps inside [min_duty, max_duty].
                if self.config.bound_alpha && alpha < -1.0 {
                    alpha = -1.0;
                    alpha_bounded = true;
                    self.counters.bounded_alphas += 1;
                }
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
        // The event reports the first bounded step of a run; a step with alpha >= -1 (or
        // without level-2 saturation, or disarmed) ends the run.
        if alpha_bounded && !self.alpha_bounding {
            self.events.push(SpinalEvent::AlphaBounded);
        }
        self.alpha_bounding = alpha_bounded;
        let mut finite = true;
        for i in 0..n {
            self.thrust[i] = self.rp_term[i]
                + (1.0 + alpha) * self.base_thrust[i]
                + (1.0 + beta) * self.yaw_term[i];
            finite &= self.thrust[i].is_finite();
        }
        if !finite {
            // A non-finite thrust (for example a huge finite rate in the gyro-moment term)
            // never reaches a motor: every rotor gets min_duty (idle while disarmed).
            self.counters.non_finite_outputs += 1;
            if !self.output_non_finite {
                self.events.push(SpinalEvent::NonFiniteOutput);
            }
            self.output_non_finite = true;
            self.alpha = -1.0;
            self.beta = -1.0;
            for i in 0..n {
                self.thrust[i] = 0.0;
                self.duty[i] = if self.start_control {
                    pwm.min_duty()
                } else {
                    IDLE_DUTY
                };
            }
            self.saturated = self.start_control;
            return;
        }
        self.output_non_finite = false;
        self.alpha = alpha;
        self.beta = beta;

        let mut saturated = alpha < 0.0;
        if self.start_control {
            for i in 0..n {
                let raw = pwm.raw_duty(self.thrust[i]);
                let clamped = pwm.clamp_duty(raw);
                saturated |= raw != clamped;
                self.duty[i] = clamped;
            }
        }
        self.saturated = saturated && self.start_control;
    }
}
