//! Parameters of the Spinal attitude estimator and their firmware values.

/// Firmware loop rate, Hz (`DELTA_T = 0.001f`).
pub const FIRMWARE_RATE_HZ: f64 = 1000.0;

/// Parameters of [`super::AttitudeEstimator`]. Defaults are the firmware's numbers at the
/// 200 Hz rate of the mirror ([`EstimatorConfig::default`]).
///
/// The filter factors are **per sample**, exactly as the firmware writes them. At a rate other
/// than 1 kHz the same factors give proportionally longer time constants (x5 at 200 Hz: gyro
/// IIR about 55 ms instead of 11 ms, gravity correction about 9 s instead of 1.8 s).
/// [`EstimatorConfig::time_matched`] rescales them to the 1 kHz time constants instead.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EstimatorConfig {
    /// Sample rate, Hz; the gyro is integrated with `dt = 1/rate_hz`.
    pub rate_hz: f64,
    /// Gyro bias calibration window at start, s (firmware 3 s); 0 disables calibration.
    pub gyro_calib_duration_s: f64,
    /// Gyro IIR factor N in `p -= p/N; p += x; out = p/N` (firmware 12).
    pub gyro_lpf_factor: f64,
    /// Accelerometer IIR factor (firmware 42).
    pub acc_lpf_factor: f64,
    /// Lower bound of the valid |a|^2, m^2/s^4 (firmware `G_MIN` 72).
    pub acc_norm_sq_min: f64,
    /// Upper bound of the valid |a|^2, m^2/s^4 (firmware `G_MAX` 133).
    pub acc_norm_sq_max: f64,
    /// Apply the accelerometer on every n-th valid sample (firmware `PRESCLAER_ACC` 3).
    pub acc_prescaler: u32,
    /// Gravity complementary factor K in `g = (K g + a)/(K+1)` (firmware 600).
    pub acc_cmpf_factor: f64,
    /// Magnetic complementary factor (firmware 250).
    pub mag_cmpf_factor: f64,
    /// Per-axis change of the magnetometer above which a sample is an outlier (firmware 20,
    /// in the driver's units, about uT).
    pub mag_outlier_threshold: f64,
    /// After more than this many consecutive outliers the new value is accepted (firmware 500).
    pub mag_outlier_max_count: u32,
    /// Accelerometer bias subtracted before filtering (firmware: from flash), m/s^2.
    pub acc_bias: [f64; 3],
    /// Magnetometer bias (ellipsoid centre), subtracted first.
    pub mag_bias: [f64; 3],
    /// Magnetometer per-axis scale, applied after the bias.
    pub mag_scale: [f64; 3],
    /// Initial body-frame heading vector of the magnetic estimate. The firmware starts from
    /// zero (no attitude until a magnetometer sample arrives); a non-zero vector here (for
    /// example `[1, 0, 0]`) lets a mirror without magnetometer report roll and pitch, with
    /// the yaw then following the integrated gyro. Not firmware behaviour.
    pub initial_heading: [f64; 3],
}

impl Default for EstimatorConfig {
    fn default() -> Self {
        Self::firmware(200.0)
    }
}

/// Why an [`EstimatorConfig`] was refused; names the field.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct EstimatorConfigError {
    /// The field at fault.
    pub field: &'static str,
    /// What is wrong with it.
    pub reason: &'static str,
}

impl core::fmt::Display for EstimatorConfigError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "{}: {}", self.field, self.reason)
    }
}

impl std::error::Error for EstimatorConfigError {}

impl EstimatorConfig {
    /// The firmware's per-sample factors, run at `rate_hz`.
    pub fn firmware(rate_hz: f64) -> Self {
        Self {
            rate_hz,
            gyro_calib_duration_s: 3.0,
            gyro_lpf_factor: 12.0,
            acc_lpf_factor: 42.0,
            acc_norm_sq_min: 72.0,
            acc_norm_sq_max: 133.0,
            acc_prescaler: 3,
            acc_cmpf_factor: 600.0,
            mag_cmpf_factor: 250.0,
            mag_outlier_threshold: 20.0,
            mag_outlier_max_count: 500,
            acc_bias: [0.0; 3],
            mag_bias: [0.0; 3],
            mag_scale: [1.0; 3],
            initial_heading: [0.0; 3],
        }
    }

    /// Factors rescaled so that `rate_hz` reproduces the firmware's 1 kHz time constants:
    /// a per-sample pole `a = 1 - 1/N` becomes `a^(1000/rate)`, and the gravity correction
    /// weight `K/(K+1)` (applied every `acc_prescaler` valid samples) likewise. The magnetic
    /// factor is left alone: it acts per new magnetometer sample, whose rate does not depend
    /// on the loop rate. Not firmware behaviour at rates other than 1 kHz.
    pub fn time_matched(rate_hz: f64) -> Self {
        let base = Self::firmware(rate_hz);
        let exponent = FIRMWARE_RATE_HZ / rate_hz;
        let iir = |n: f64| 1.0 / (1.0 - (1.0 - 1.0 / n).powf(exponent));
        let cmpf = |k: f64| {
            let a = (k / (k + 1.0)).powf(exponent);
            a / (1.0 - a)
        };
        Self {
            gyro_lpf_factor: iir(base.gyro_lpf_factor),
            acc_lpf_factor: iir(base.acc_lpf_factor),
            acc_cmpf_factor: cmpf(base.acc_cmpf_factor),
            ..base
        }
    }

    /// Sample period `1/rate_hz`, s.
    pub fn dt(&self) -> f64 {
        1.0 / self.rate_hz
    }

    /// Number of samples in the gyro calibration window (`round(duration * rate)`).
    pub fn gyro_calib_samples(&self) -> u64 {
        let samples = (self.gyro_calib_duration_s * self.rate_hz).round();
        if samples >= 1.0 {
            samples as u64
        } else {
            0
        }
    }

    /// Checks every field.
    pub fn validate(&self) -> Result<(), EstimatorConfigError> {
        let fail = |field, reason| Err(EstimatorConfigError { field, reason });
        if !(self.rate_hz.is_finite() && self.rate_hz > 0.0 && self.rate_hz <= 10_000.0) {
            return fail("rate_hz", "must be in (0, 10000]");
        }
        if !(self.gyro_calib_duration_s.is_finite()
            && (0.0..=3600.0).contains(&self.gyro_calib_duration_s))
        {
            return fail("gyro_calib_duration_s", "must be in [0, 3600]");
        }
        for (value, field) in [
            (self.gyro_lpf_factor, "gyro_lpf_factor"),
            (self.acc_lpf_factor, "acc_lpf_factor"),
        ] {
            if !(value.is_finite() && value >= 1.0) {
                return fail(field, "must be finite and >= 1");
            }
        }
        for (value, field) in [
            (self.acc_cmpf_factor, "acc_cmpf_factor"),
            (self.mag_cmpf_factor, "mag_cmpf_factor"),
            (self.mag_outlier_threshold, "mag_outlier_threshold"),
            (self.acc_norm_sq_min, "acc_norm_sq_min"),
        ] {
            if !(value.is_finite() && value >= 0.0) {
                return fail(field, "must be finite and >= 0");
            }
        }
        if !(self.acc_norm_sq_max.is_finite() && self.acc_norm_sq_max > self.acc_norm_sq_min) {
            return fail("acc_norm_sq_max", "must be finite and > acc_norm_sq_min");
        }
        if self.acc_prescaler == 0 {
            return fail("acc_prescaler", "must be >= 1");
        }
        for (values, field) in [
            (self.acc_bias, "acc_bias"),
            (self.mag_bias, "mag_bias"),
            (self.mag_scale, "mag_scale"),
            (self.initial_heading, "initial_heading"),
        ] {
            if values.iter().any(|v| !v.is_finite()) {
                return fail(field, "must be finite");
            }
        }
        Ok(())
    }
}
