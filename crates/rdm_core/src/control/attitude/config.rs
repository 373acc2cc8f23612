//! Parameters of the Spinal attitude controller (`jsk-wire-protocols.md` sec. 3.4-3.7) and
//! the guards it adds to the firmware (docs/spinal.md "Guards on the actuator path").

use crate::pwm::VoltageGuard;

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
    /// Battery-voltage plausibility guard of the PWM conversion; default a cell window
    /// (cells from the reference curves, 3.0-4.45 V per cell); `VoltageGuard::Off` is
    /// firmware-exact.
    pub voltage_guard: VoltageGuard,
    /// Saturate each FourAxisCommand base thrust into `[0, command_thrust_max]` and the yaw
    /// term into `[-command_thrust_max, command_thrust_max]` (the largest reference
    /// `max_thrust` times the rotor divider); default true, false is firmware-exact.
    pub saturate_commands: bool,
    /// Bound the base-thrust saturation factor alpha to `[-1, 0]` (docs/spinal.md "Attitude
    /// allocation"): `1 + alpha >= 0` keeps every base thrust's sign, and the duty clamp keeps
    /// every output inside `[min_duty, max_duty]`. Default true, counted
    /// (`ControlCounters::bounded_alphas`); false is firmware-exact (alpha < -1 when one
    /// rotor's roll/pitch term alone exceeds the thrust limit, which reverses every base
    /// thrust).
    pub bound_alpha: bool,
    /// ESC outputs the board drives (1..=[`crate::MAX_ROTORS`]): the length of every
    /// per-rotor output, and the largest `uav_info.motor_num` accepted. ASSUMPTION: 4 by
    /// default, the paper's RDM; a robot description with another rotor count sets its own.
    pub motor_outputs: usize,
}

impl Default for AttitudeControlConfig {
    fn default() -> Self {
        Self {
            rate_hz: 200.0,
            anti_windup: AntiWindup::ClampAndConditional { limit: 1.0 },
            command_timeout_s: 0.5,
            max_tilt_rad: 1.0,
            force_landing_rate: FIRMWARE_FORCE_LANDING_STEP * 1000.0,
            voltage_guard: VoltageGuard::default(),
            saturate_commands: true,
            bound_alpha: true,
            motor_outputs: 4,
        }
    }
}

impl AttitudeControlConfig {
    /// Firmware-exact behaviour at `rate_hz`: no anti-windup, no voltage guard, no command
    /// saturation, no alpha bound. The duty cap (`min_duty <= max_duty`, a non-finite thrust -> `min_duty`)
    /// holds in every configuration.
    pub fn firmware(rate_hz: f64) -> Self {
        Self {
            rate_hz,
            anti_windup: AntiWindup::Off,
            voltage_guard: VoltageGuard::Off,
            saturate_commands: false,
            bound_alpha: false,
            ..Self::default()
        }
    }

    /// Checks every field; names the field at fault.
    pub fn validate(&self) -> Result<(), &'static str> {
        if !(self.rate_hz.is_finite() && self.rate_hz > 0.0 && self.rate_hz <= 10_000.0) {
            return Err("rate_hz");
        }
        if crate::check_rotor_count(self.motor_outputs).is_err() {
            return Err("motor_outputs");
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
        self.voltage_guard.validate()
    }
}
