//! Parameters of the Spinal attitude estimator and their firmware values.

/// Firmware loop rate, Hz (`DELTA_T = 0.001f`).
pub const FIRMWARE_RATE_HZ: f64 = 1000.0;

/// Two LSB of a 32767-count full scale: the int16 reading -32768 is one LSB beyond the
/// scale, the second absorbs the rounding of the count -> unit conversion.
const TWO_LSB_MARGIN: f64 = 32769.0 / 32767.0;
/// Gyro range, rad/s: the ICM-20948 / MPU-9250 +-2000 dps setting (sec. 2.4, 3.2) plus two
/// LSB.
pub const GYRO_FULL_SCALE: f64 = 2000.0 * core::f64::consts::PI / 180.0 * TWO_LSB_MARGIN;
/// Accelerometer range, m/s^2: the +-8 g setting (sec. 2.4, 3.2) plus two LSB.
pub const ACC_FULL_SCALE: f64 = 8.0 * 9.80665 * TWO_LSB_MARGIN;
/// Largest configurable sensor range (gyro rad/s, accelerometer m/s^2): with it every
/// filter state stays finite whatever the accepted samples (IIR states below 1e9 x factor,
/// bias sums below 1e9 x 3.6e7 samples, a rotation step below 1e9 x dt).
pub const MAX_SENSOR_RANGE: f64 = 1.0e9;

/// The estimator's guards against samples and states the firmware does not expect (not in
/// the firmware; docs/spinal.md "Estimator guards"). `EstimatorConfig::guards = None` is
/// firmware-exact.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EstimatorGuards {
    /// A sample with any |gyro| axis above this is rejected (`InvalidInput`, counted as
    /// `out_of_range`), rad/s. Default [`GYRO_FULL_SCALE`].
    pub gyro_range: f64,
    /// A sample with any |acc| axis above this is rejected, m/s^2. Default
    /// [`ACC_FULL_SCALE`].
    pub acc_range: f64,
    /// Status `Degraded` while the gravity estimate and the last valid accelerometer sample
    /// differ by more than this, rad. Default 20 deg.
    pub degraded_angle_rad: f64,
    /// The gravity estimate is re-initialised from the accelerometer once valid samples
    /// differ from it by more than this for `reinit_hold_s`, rad. Default 60 deg.
    pub reinit_angle_rad: f64,
    /// How long (in valid accelerometer samples x dt) the `reinit_angle_rad` disagreement
    /// must last, s. Default 0.5 s.
    pub reinit_hold_s: f64,
}

impl Default for EstimatorGuards {
    fn default() -> Self {
        Self {
            gyro_range: GYRO_FULL_SCALE,
            acc_range: ACC_FULL_SCALE,
            degraded_angle_rad: 20.0_f64.to_radians(),
            reinit_angle_rad: 60.0_f64.to_radians(),
            reinit_hold_s: 0.5,
        }
    }
}

impl EstimatorGuards {
    fn validate(&self) -> Result<(), EstimatorConfigError> {
        let fail = |field, reason| Err(EstimatorConfigError { field, reason });
        for (value, field) in [
            (self.gyro_range, "gyro_range"),
            (self.acc_range, "acc_range"),
        ] {
            if !(value.is_finite() && value > 0.0 && value <= MAX_SENSOR_RANGE) {
                return fail(field, "must be in (0, 1e9]");
            }
        }
        let pi = core::f64::consts::PI;
        if !(self.degraded_angle_rad > 0.0 && self.degraded_angle_rad <= pi) {
            return fail("degraded_angle_rad", "must be in (0, pi]");
        }
        if !(self.reinit_angle_rad >= self.degraded_angle_rad && self.reinit_angle_rad <= pi) {
            return fail("reinit_angle_rad", "must be in [degraded_angle_rad, pi]");
        }
        if !(self.reinit_hold_s.is_finite() && (0.0..=3600.0).contains(&self.reinit_hold_s)) {
            return fail("reinit_hold_s", "must be in [0, 3600]");
        }
        Ok(())
    }
}

/// Parameters of [`super::AttitudeEstimator`]. Defaults are the firmware's numbers at the
/// 200 Hz rate of the mirror with the default [`EstimatorGuards`]
/// ([`EstimatorConfig::default`] = [`EstimatorConfig::new`]`(200.0)`);
/// [`EstimatorConfig::firmware`] is firmware-exact (no guards).
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
    /// Sample range checks and filter recovery; `None` is firmware-exact.
    pub guards: Option<EstimatorGuards>,
}

impl Default for EstimatorConfig {
    fn default() -> Self {
        Self::new(200.0)
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
    /// The firmware's per-sample factors at `rate_hz` with the default guards.
    pub fn new(rate_hz: f64) -> Self {
        Self {
            guards: Some(EstimatorGuards::default()),
            ..Self::firmware(rate_hz)
        }
    }

    /// Firmware-exact: the firmware's per-sample factors at `rate_hz`, no guards.
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
            guards: None,
        }
    }

    /// Factors rescaled so that `rate_hz` reproduces the firmware's 1 kHz time constants:
    /// a per-sample pole `a = 1 - 1/N` becomes `a^(1000/rate)`, and the gravity correction
    /// weight `K/(K+1)` (applied every `acc_prescaler` valid samples) likewise. The magnetic
    /// factor is left alone: it acts per new magnetometer sample, whose rate does not depend
    /// on the loop rate. Not firmware behaviour at rates other than 1 kHz. Default guards.
    pub fn time_matched(rate_hz: f64) -> Self {
        let base = Self::new(rate_hz);
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
        match &self.guards {
            Some(guards) => guards.validate(),
            None => Ok(()),
        }
    }
}
