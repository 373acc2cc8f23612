//! Duty encodings: the `motor_pwms` report, the Neuron CAN motor value and DShot
//! (`jsk-wire-protocols.md` sec. 2.4 "Motor PWM", sec. 3.6).

/// Lowest DShot throttle value (firmware `DSHOT_MIN_THROTTLE`).
pub const DSHOT_MIN_THROTTLE: u16 = 48;
/// Highest DShot throttle value (firmware `DSHOT_MAX_THROTTLE`).
pub const DSHOT_MAX_THROTTLE: u16 = 2047;
/// DShot throttle span mapped onto duty 0.5..1.0 (firmware `DSHOT_RANGE`).
pub const DSHOT_RANGE: f64 = 1999.0;

/// Truncates a non-negative value into `u16` range (the firmware's implicit casts).
fn saturating_trunc_u16(value: f64) -> u16 {
    if value.is_nan() || value <= 0.0 {
        0
    } else if value >= f64::from(u16::MAX) {
        u16::MAX
    } else {
        value as u16
    }
}

/// The `motor_pwms` report value: `(uint16)(duty * 2000)`, i.e. the pulse in us.
pub fn duty_to_report(duty: f64) -> u16 {
    saturating_trunc_u16(duty * 2000.0)
}

/// Largest Neuron CAN motor value (pulse 2000 us, duty 1.0; sec. 2.4 "Motor PWM").
pub const CAN_PWM_VALUE_MAX: u16 = 1000;

/// The Neuron CAN motor value: `(uint16)(duty * 2000 - 1000)` (pulse - 1000 us), clamped to
/// 0..=1000: duties below 0.5 give 0 instead of the firmware's wrap-around, duties above 1.0
/// give 1000 instead of a value the 10-bit slot cannot carry.
pub fn duty_to_can_value(duty: f64) -> u16 {
    saturating_trunc_u16(duty * 2000.0 - 1000.0).min(CAN_PWM_VALUE_MAX)
}

/// The DShot throttle: `(duty - 0.5) / 0.5 * 1999 + 48`, truncated and clamped to 48..=2047.
pub fn duty_to_dshot(duty: f64) -> u16 {
    let value = (duty - 0.5) / 0.5 * DSHOT_RANGE + f64::from(DSHOT_MIN_THROTTLE);
    saturating_trunc_u16(value).clamp(DSHOT_MIN_THROTTLE, DSHOT_MAX_THROTTLE)
}
