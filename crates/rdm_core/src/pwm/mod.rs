//! Thrust to PWM conversion as the Spinal firmware performs it
//! (`jsk-wire-protocols.md` sec. 3.5-3.6, `pwmConversion`).
//!
//! The converter holds the `motor_info` parameters (a `spinal/PwmInfo` message), picks the
//! reference curve whose voltage is closest to the battery voltage (every 500 ms), scales the
//! thrust by the voltage factor and inverts the thrust curve into a duty in `[min_duty,
//! max_duty]`. Duty 0.5 is a 1000 us pulse (motor stopped).
//!
//! Guards that the firmware does not have (docs/spinal.md "Guards on the actuator path"):
//! a battery voltage outside the plausible window of the battery's cell count is rejected,
//! counted and replaced by the last good one ([`VoltageGuard`]; `VoltageGuard::Off` is the
//! firmware's acceptance of any positive voltage); `min_duty` never exceeds `max_duty`, and a
//! non-finite duty gives `min_duty`, in every mode.

/// Duty that stops a motor (1000 us pulse at the 2 ms PWM period).
pub const IDLE_DUTY: f64 = 0.5;
/// How many reference curves (`MotorInfo`) a converter can hold.
pub const MAX_MOTOR_INFO: usize = 8;
/// Interval between reference-voltage selections, s (firmware: `> 500` ms).
pub const VOLTAGE_UPDATE_INTERVAL_S: f64 = 0.5;

mod encode;
mod voltage_guard;

pub use encode::{
    duty_to_can_value, duty_to_dshot, duty_to_report, CAN_PWM_VALUE_MAX, DSHOT_MAX_THROTTLE,
    DSHOT_MIN_THROTTLE, DSHOT_RANGE,
};
pub use voltage_guard::{
    cells_from_reference, VoltageGuard, CELL_FULL_V, CELL_MAX_V, CELL_MIN_V, MAX_CELLS,
};

/// How a thrust is inverted into a PWM percentage (`MotorInfo.SQRT_MODE`/`POLYNOMINAL_MODE`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PwmMode {
    /// Mode 0: solve `f = 0.1 p2 x^2 + 0.1 p1 x + p0` for x in %; voltage factor `(Vref/V)^2`.
    Sqrt,
    /// Mode 1: `x = sum_j p_j (f/10)^j`, j = 0..4; voltage factor `(Vref/V)^1.5`.
    Polynomial,
}

impl PwmMode {
    /// The mode for the wire byte `pwm_conversion_mode`, if it is known.
    pub fn from_wire(mode: u8) -> Option<Self> {
        match mode {
            0 => Some(Self::Sqrt),
            1 => Some(Self::Polynomial),
            _ => None,
        }
    }
}

/// One reference thrust curve (`spinal/MotorInfo`).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct MotorInfo {
    /// Battery voltage the curve was measured at, V.
    pub voltage: f64,
    /// Largest thrust of one rotor at that voltage, N.
    pub max_thrust: f64,
    /// Curve coefficients `p0..p4` (SQRT mode uses p0..p2, p1 and p2 "x10" as in the yaml).
    pub polynomial: [f64; 5],
}

/// The `spinal/PwmInfo` parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PwmInfo {
    /// Lowest duty while armed (replaced by `convert(min_thrust)` when `min_thrust > 0`).
    pub min_pwm: f64,
    /// Highest duty.
    pub max_pwm: f64,
    /// Thrust of one rotor that defines the lowest duty, N (0: use `min_pwm`).
    pub min_thrust: f64,
    /// Average base thrust at which the force-landing ramp stops, N.
    pub force_landing_thrust: f64,
    /// Curve inversion mode.
    pub mode: PwmMode,
    /// Reference curves; only the first `n_motor_info` are used.
    pub motor_info: [MotorInfo; MAX_MOTOR_INFO],
    /// Number of valid entries in `motor_info` (at least 1).
    pub n_motor_info: usize,
}

/// Why a [`PwmInfo`] was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PwmInfoError {
    /// `motor_info` is empty or longer than [`MAX_MOTOR_INFO`].
    MotorInfoCount,
    /// A number is NaN or infinite; the field is named.
    NonFinite(&'static str),
    /// A reference voltage is not positive.
    NonPositiveVoltage,
    /// SQRT mode needs `p2 != 0`.
    ZeroQuadraticCoefficient,
    /// `min_pwm` or `max_pwm` outside `[0, 1]` (a duty is a fraction of the PWM period).
    DutyRange(&'static str),
    /// A [`VoltageGuard`] field out of range; the field is named.
    VoltageGuard(&'static str),
}

impl core::fmt::Display for PwmInfoError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::MotorInfoCount => write!(f, "motor_info: need 1..={MAX_MOTOR_INFO} entries"),
            Self::NonFinite(field) => write!(f, "{field}: not finite"),
            Self::NonPositiveVoltage => write!(f, "motor_info.voltage: must be > 0"),
            Self::ZeroQuadraticCoefficient => {
                write!(f, "motor_info.polynomial[2]: must be non-zero in SQRT mode")
            }
            Self::DutyRange(field) => write!(f, "{field}: must be a duty in [0, 1]"),
            Self::VoltageGuard(field) => write!(f, "{field}: out of range"),
        }
    }
}

impl std::error::Error for PwmInfoError {}

impl PwmInfo {
    /// Builds and checks a `PwmInfo` from a slice of reference curves.
    pub fn new(
        min_pwm: f64,
        max_pwm: f64,
        min_thrust: f64,
        force_landing_thrust: f64,
        mode: PwmMode,
        curves: &[MotorInfo],
    ) -> Result<Self, PwmInfoError> {
        if curves.is_empty() || curves.len() > MAX_MOTOR_INFO {
            return Err(PwmInfoError::MotorInfoCount);
        }
        let mut motor_info = [MotorInfo::default(); MAX_MOTOR_INFO];
        motor_info[..curves.len()].copy_from_slice(curves);
        let info = Self {
            min_pwm,
            max_pwm,
            min_thrust,
            force_landing_thrust,
            mode,
            motor_info,
            n_motor_info: curves.len(),
        };
        info.validate()?;
        Ok(info)
    }

    /// Checks every field; see [`PwmInfoError`].
    pub fn validate(&self) -> Result<(), PwmInfoError> {
        if self.n_motor_info == 0 || self.n_motor_info > MAX_MOTOR_INFO {
            return Err(PwmInfoError::MotorInfoCount);
        }
        for (value, name) in [
            (self.min_pwm, "min_pwm"),
            (self.max_pwm, "max_pwm"),
            (self.min_thrust, "min_thrust"),
            (self.force_landing_thrust, "force_landing_thrust"),
        ] {
            if !value.is_finite() {
                return Err(PwmInfoError::NonFinite(name));
            }
        }
        for (value, name) in [(self.min_pwm, "min_pwm"), (self.max_pwm, "max_pwm")] {
            if !(0.0..=1.0).contains(&value) {
                return Err(PwmInfoError::DutyRange(name));
            }
        }
        for curve in self.curves() {
            if !curve.voltage.is_finite() {
                return Err(PwmInfoError::NonFinite("motor_info.voltage"));
            }
            if !curve.max_thrust.is_finite() {
                return Err(PwmInfoError::NonFinite("motor_info.max_thrust"));
            }
            if curve.polynomial.iter().any(|p| !p.is_finite()) {
                return Err(PwmInfoError::NonFinite("motor_info.polynomial"));
            }
            if curve.voltage <= 0.0 {
                return Err(PwmInfoError::NonPositiveVoltage);
            }
            if self.mode == PwmMode::Sqrt && curve.polynomial[2] == 0.0 {
                return Err(PwmInfoError::ZeroQuadraticCoefficient);
            }
        }
        Ok(())
    }

    /// The valid reference curves.
    pub fn curves(&self) -> &[MotorInfo] {
        self.motor_info.get(..self.n_motor_info).unwrap_or(&[])
    }

    /// The Hydrus quad example of the fact sheet (`MotorInfo.yaml`, sec. 3.6), one reference
    /// curve at 25.2 V. Used by tests and examples.
    pub fn hydrus_example() -> Self {
        let curve = MotorInfo {
            voltage: 25.2,
            max_thrust: 20.0,
            polynomial: [12.3593793002, -6.627443098, 0.07983707, 0.0, 0.0],
        };
        let mut motor_info = [MotorInfo::default(); MAX_MOTOR_INFO];
        motor_info[0] = curve;
        Self {
            min_pwm: 0.59,
            max_pwm: 0.9375,
            min_thrust: 1.0,
            force_landing_thrust: 6.5,
            mode: PwmMode::Sqrt,
            motor_info,
            n_motor_info: 1,
        }
    }
}

/// Inverts the thrust curve of one reference: the raw duty (pwm% / 100), before clamping.
///
/// `scaled_thrust` already includes the voltage factor and the rotor divider. Negative
/// thrust is raised to 0 as in the firmware. In SQRT mode a negative discriminant (a thrust
/// below the curve's vertex) is taken as 0 instead of the firmware's NaN, so the result is
/// always finite for finite input.
pub fn curve_duty(mode: PwmMode, curve: &MotorInfo, scaled_thrust: f64) -> f64 {
    let f = scaled_thrust.max(0.0);
    let p = &curve.polynomial;
    let pwm_percent = match mode {
        PwmMode::Sqrt => {
            // f = 0.1 p2 x^2 + 0.1 p1 x + p0 (the yaml stores p1, p2 "x10").
            let discriminant = (p[1] * p[1] - 40.0 * p[2] * (p[0] - f)).max(0.0);
            (-p[1] + discriminant.sqrt()) / (2.0 * p[2])
        }
        PwmMode::Polynomial => {
            let tenth = f * 0.1;
            p.iter().rev().fold(0.0, |acc, &c| acc * tenth + c)
        }
    };
    pwm_percent / 100.0
}

/// Voltage factor of a mode: `(Vref/V)^2` (SQRT) or `(Vref/V)^1.5` (POLY).
pub fn voltage_factor(mode: PwmMode, reference_voltage: f64, voltage: f64) -> f64 {
    let ratio = reference_voltage / voltage;
    match mode {
        PwmMode::Sqrt => ratio * ratio,
        PwmMode::Polynomial => ratio * ratio.sqrt(),
    }
}

/// The stateful converter: reference selection, voltage factor, min duty, clamping.
#[derive(Clone, Debug)]
pub struct PwmConverter {
    info: PwmInfo,
    reference_index: usize,
    v_factor: f64,
    min_duty: f64,
    last_voltage_update_s: Option<f64>,
    rejected_voltages: u64,
    rotor_divider: f64,
    voltage_window: Option<(f64, f64)>,
    last_good_voltage: f64,
}

impl PwmConverter {
    /// A converter for checked parameters with the default [`VoltageGuard`]. Until the first
    /// voltage update the factor is 1 and the reference is the first curve, as in the
    /// firmware.
    pub fn new(info: PwmInfo) -> Result<Self, PwmInfoError> {
        Self::with_guard(info, VoltageGuard::default())
    }

    /// A converter for checked parameters and a voltage guard (`VoltageGuard::Off`:
    /// firmware-exact voltage handling). An invalid guard is refused as
    /// `PwmInfoError::VoltageGuard`.
    pub fn with_guard(info: PwmInfo, guard: VoltageGuard) -> Result<Self, PwmInfoError> {
        info.validate()?;
        guard.validate().map_err(PwmInfoError::VoltageGuard)?;
        Ok(Self {
            min_duty: info.min_pwm.min(info.max_pwm),
            reference_index: 0,
            v_factor: 1.0,
            last_voltage_update_s: None,
            rejected_voltages: 0,
            rotor_divider: 1.0,
            voltage_window: guard.window(&info),
            last_good_voltage: info.motor_info[0].voltage,
            info,
        })
    }

    /// The parameters in use.
    pub fn info(&self) -> &PwmInfo {
        &self.info
    }

    /// Index of the reference curve in use.
    pub fn reference_index(&self) -> usize {
        self.reference_index
    }

    /// The voltage factor in use.
    pub fn voltage_factor(&self) -> f64 {
        self.v_factor
    }

    /// Lowest duty in use (from `min_thrust` after the first voltage update if it is > 0),
    /// never above `max_duty`.
    pub fn min_duty(&self) -> f64 {
        self.min_duty
    }

    /// Highest duty.
    pub fn max_duty(&self) -> f64 {
        self.info.max_pwm
    }

    /// The plausible battery voltage window `(low, high)`, V; `None`: guard off.
    pub fn voltage_window(&self) -> Option<(f64, f64)> {
        self.voltage_window
    }

    /// The last voltage that passed the guard (at first the first reference's voltage).
    pub fn last_good_voltage(&self) -> f64 {
        self.last_good_voltage
    }

    /// Sets how many rotors share one commanded thrust (firmware `rotor_devider_`: 2 for
    /// DRAGON, else 1). Values below 1 or not finite are ignored.
    pub fn set_rotor_divider(&mut self, rotor_divider: f64) {
        if rotor_divider.is_finite() && rotor_divider >= 1.0 {
            self.rotor_divider = rotor_divider;
        }
    }

    /// How many rotors share one commanded thrust.
    pub fn rotor_divider(&self) -> f64 {
        self.rotor_divider
    }

    /// How many voltages were rejected: not finite and positive, or (guard on) outside the
    /// plausible window.
    pub fn rejected_voltages(&self) -> u64 {
        self.rejected_voltages
    }

    /// Largest base thrust a command can ask of one motor: the largest `max_thrust` of the
    /// reference curves times the rotor divider, N.
    pub fn command_thrust_max(&self) -> f64 {
        let top = self
            .info
            .curves()
            .iter()
            .map(|c| c.max_thrust)
            .fold(0.0_f64, f64::max);
        top * self.rotor_divider
    }

    fn reference(&self) -> &MotorInfo {
        self.info
            .motor_info
            .get(self.reference_index)
            .unwrap_or(&self.info.motor_info[0])
    }

    /// Whether the guard lets `voltage` through (finite and positive in every case).
    fn plausible(&self, voltage: f64) -> bool {
        if !(voltage.is_finite() && voltage > 0.0) {
            return false;
        }
        self.voltage_window
            .is_none_or(|(low, high)| (low..=high).contains(&voltage))
    }

    /// Selects the reference curve and voltage factor when more than 500 ms passed since the
    /// last selection (or none was made yet). Returns whether `voltage` was used. A rejected
    /// voltage is counted; with the guard on, the last good voltage is selected instead and
    /// the 500 ms schedule goes on; with it off, the voltage is ignored.
    pub fn update_voltage(&mut self, voltage: f64, now_s: f64) -> bool {
        if let Some(last) = self.last_voltage_update_s {
            // NaN time never triggers an update.
            let due = now_s - last > VOLTAGE_UPDATE_INTERVAL_S;
            if !due {
                return false;
            }
        }
        if !now_s.is_finite() {
            self.rejected_voltages += 1;
            return false;
        }
        let used = self.force_voltage(voltage);
        if used || self.voltage_window.is_some() {
            self.last_voltage_update_s = Some(now_s);
        }
        used
    }

    /// Selects the reference for `voltage` now, regardless of the 500 ms schedule; returns
    /// whether `voltage` was used (a rejected one is counted and, guard on, replaced by the
    /// last good voltage). The first curve with the smallest |V - Vref| wins, as in the
    /// firmware's strict `>`.
    pub fn force_voltage(&mut self, voltage: f64) -> bool {
        if self.plausible(voltage) {
            self.last_good_voltage = voltage;
            self.select(voltage);
            true
        } else {
            self.rejected_voltages += 1;
            if self.voltage_window.is_some() {
                self.select(self.last_good_voltage);
            }
            false
        }
    }

    fn select(&mut self, voltage: f64) {
        let mut best = f64::INFINITY;
        for (index, curve) in self.info.curves().iter().enumerate() {
            let diff = (voltage - curve.voltage).abs();
            if best > diff {
                best = diff;
                self.reference_index = index;
            }
        }
        self.v_factor = voltage_factor(self.info.mode, self.reference().voltage, voltage);
        if self.info.min_thrust > 0.0 {
            // As the firmware: convert() includes the rotor divider here too. Capped at
            // max_pwm (the firmware's clamp would let min_duty > max_duty through); a
            // non-finite value (an infinite voltage factor) falls back to min_pwm.
            let raw = self.raw_duty(self.info.min_thrust);
            self.min_duty = if raw.is_finite() {
                raw.min(self.info.max_pwm)
            } else {
                self.info.min_pwm.min(self.info.max_pwm)
            };
        }
    }

    /// Largest thrust of one rotor group at the current voltage (`max_thrust / v_factor`).
    pub fn thrust_limit(&self) -> f64 {
        self.reference().max_thrust / self.v_factor
    }

    /// Unclamped duty of a commanded thrust (firmware `convert`:
    /// `f = v_factor * thrust / rotor_divider`, then the curve inversion).
    pub fn raw_duty(&self, thrust: f64) -> f64 {
        curve_duty(
            self.info.mode,
            self.reference(),
            self.v_factor * thrust / self.rotor_divider,
        )
    }

    /// Clamps a duty into `[min_duty, max_duty]`; a non-finite duty becomes `min_duty`
    /// (the firmware would pass NaN to the timer and clamp +inf to `max_duty`).
    pub fn clamp_duty(&self, duty: f64) -> f64 {
        if !duty.is_finite() || duty < self.min_duty {
            self.min_duty
        } else if duty > self.info.max_pwm {
            self.info.max_pwm
        } else {
            duty
        }
    }

    /// Clamped duty of a thrust, as the firmware outputs it while armed.
    pub fn duty(&self, thrust: f64) -> f64 {
        self.clamp_duty(self.raw_duty(thrust))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sqrt_mode_round_trips_through_the_quadratic() {
        let info = PwmInfo::hydrus_example();
        let curve = info.motor_info[0];
        for f in [1.0, 5.0, 10.0, 19.0] {
            let x = curve_duty(PwmMode::Sqrt, &curve, f) * 100.0;
            let p = curve.polynomial;
            let back = 0.1 * p[2] * x * x + 0.1 * p[1] * x + p[0];
            assert!((back - f).abs() < 1e-9, "{f} -> {x} -> {back}");
        }
    }

    #[test]
    fn dshot_is_clamped() {
        assert_eq!(duty_to_dshot(0.4), DSHOT_MIN_THROTTLE);
        assert_eq!(duty_to_dshot(1.2), DSHOT_MAX_THROTTLE);
    }
}
