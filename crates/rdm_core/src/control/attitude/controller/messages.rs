//! The messages of the Spinal attitude controller: `uav_info`, `motor_info`,
//! `flight_config_cmd`, `four_axes/command`, gains, matrices and the desired coordinate
//! (`jsk-wire-protocols.md` sec. 3.4, 3.7), each validated before it changes the state.

use super::super::events::{CommandError, FlightConfigCmd, SpinalEvent};
use super::super::wire::{from_wire, inertia_from_wire, inertia_matrix, RollPitchYawTermWire};
use super::{AttitudeController, UAV_MODEL_DRAGON};
use crate::control::gains::GainSet;
use crate::estimate::rotation_from_euler;
use crate::pwm::{PwmConverter, PwmInfo, IDLE_DUTY};
use crate::MAX_ROTORS;

impl AttitudeController {
    /// `uav_info`: motor number and model. As the firmware: a motor number different from
    /// an already known one sets it to 0 (blocks arming); DRAGON sets the rotor divider 2.
    pub fn set_uav_info(&mut self, motor_num: u8, uav_model: u8) -> Result<(), CommandError> {
        let motors = usize::from(motor_num);
        if motors > self.config.motor_outputs {
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

    /// `motor_info` (`PwmInfo`): thrust curves and duty limits. The converter gets the
    /// configured voltage guard; its voltage selection starts again (factor 1 until the next
    /// step's update).
    pub fn set_pwm_info(&mut self, info: PwmInfo) -> Result<(), CommandError> {
        match PwmConverter::with_guard(info, self.config.voltage_guard) {
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
    /// the base thrust per rotor. With `saturate_commands` (the default) each base thrust is
    /// saturated into `[0, command_thrust_max]` and the yaw term into
    /// `[-command_thrust_max, command_thrust_max]`; a command with a saturated value is
    /// counted (`saturated_commands`) and the first of a run reported
    /// (`SpinalEvent::CommandSaturated`).
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
        let n = self.motor_number.min(MAX_ROTORS);
        let mut base = [0.0; MAX_ROTORS];
        for (dst, &src) in base.iter_mut().zip(base_thrust) {
            *dst = src;
        }
        let mut yaw = angles[2];
        if self.config.saturate_commands {
            self.saturate_command(&mut base[..n], &mut yaw);
        }
        if self.force_landing {
            let average = base[..n].iter().sum::<f64>() / n as f64;
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
        for (i, &thrust) in base.iter().enumerate().take(n) {
            self.base_thrust[i] = thrust;
            if let Some(imax) = self.max_yaw_index {
                self.extra_yaw[i] = yaw * self.d_gain[i][2] / self.d_gain[imax][2];
            }
        }
        Ok(())
    }

    /// Saturates a command's base thrusts into `[0, max]` and its yaw term into
    /// `[-max, max]`, `max` = [`PwmConverter::command_thrust_max`] (0 before `motor_info`);
    /// counts and reports a command that needed it.
    ///
    /// ASSUMPTION: no motor can be asked for more than the largest `max_thrust` of its
    /// reference curves (times the rotor divider); the firmware's saturation factor alpha
    /// then scales the thrust to the limit at the present voltage. Without this, a base
    /// thrust of 3.4e38 (a float32 the wire carries) gives alpha = -1 exactly (the residual
    /// `limit - base` rounds to `-base`), so `(1 + alpha) base = 0`: the motors fall to
    /// `min_duty`.
    fn saturate_command(&mut self, base: &mut [f64], yaw: &mut f64) {
        let max = self.pwm.as_ref().map_or(0.0, |p| p.command_thrust_max());
        let mut saturated = false;
        for value in base.iter_mut() {
            let clamped = value.clamp(0.0, max);
            saturated |= clamped != *value;
            *value = clamped;
        }
        let clamped = yaw.clamp(-max, max);
        saturated |= clamped != *yaw;
        *yaw = clamped;
        if saturated {
            self.counters.saturated_commands += 1;
            if !self.command_saturating {
                self.events.push(SpinalEvent::CommandSaturated);
            }
        }
        self.command_saturating = saturated;
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
            for (i, t) in terms.iter().enumerate().take(MAX_ROTORS) {
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
        for i in 0..self.motor_number.min(MAX_ROTORS) {
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
        for i in 0..self.motor_number.min(MAX_ROTORS) {
            if self.d_gain[i][2] > best {
                best = self.d_gain[i][2];
                self.max_yaw_index = Some(i);
            }
        }
    }

    /// Firmware `reset()` (on ARM_OFF): gains, integrals, terms and the fail-safe timer
    /// cleared, targets zero, every duty to idle. Vehicle description and PWM info stay.
    fn reset(&mut self, now_s: f64) {
        self.thrust = [0.0; MAX_ROTORS];
        self.duty = [IDLE_DUTY; MAX_ROTORS];
        self.base_thrust = [0.0; MAX_ROTORS];
        self.rp_term = [0.0; MAX_ROTORS];
        self.yaw_term = [0.0; MAX_ROTORS];
        self.extra_yaw = [0.0; MAX_ROTORS];
        self.p_gain = [[0.0; 3]; MAX_ROTORS];
        self.i_gain = [[0.0; 3]; MAX_ROTORS];
        self.d_gain = [[0.0; 3]; MAX_ROTORS];
        self.torque_allocation_inv = [[0.0; 3]; MAX_ROTORS];
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
}
