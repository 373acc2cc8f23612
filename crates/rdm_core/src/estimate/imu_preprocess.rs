//! IMU preprocessing as Spinal's `IMU::process` does it (`jsk-wire-protocols.md` sec. 3.2):
//! gyro bias calibration, first-order IIR filters, magnetometer calibration and outlier
//! rejection.

use nalgebra::Vector3;

use super::config::EstimatorConfig;

/// Filtered sensor values of one sample.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FilteredImu {
    /// Bias-corrected, low-passed angular velocity, rad/s (body frame).
    pub gyro: Vector3<f64>,
    /// Bias-corrected, low-passed specific force, m/s^2.
    pub acc: Vector3<f64>,
    /// Calibrated magnetometer value that passed the outlier filter.
    pub mag: Vector3<f64>,
}

/// The firmware's first-order IIR `p -= p/N; p += x; out = p/N`, written out literally so
/// the rounding matches the firmware order of operations.
#[derive(Clone, Copy, Debug)]
struct Iir {
    factor: f64,
    p: Vector3<f64>,
}

impl Iir {
    fn new(factor: f64) -> Self {
        Self {
            factor,
            p: Vector3::zeros(),
        }
    }

    fn step(&mut self, x: &Vector3<f64>) -> Vector3<f64> {
        self.p -= self.p / self.factor;
        self.p += x;
        self.p / self.factor
    }
}

/// Gyro calibration, IIR filters and magnetometer outlier rejection.
#[derive(Clone, Debug)]
pub struct ImuPreprocessor {
    calib_samples: u64,
    calib_count: u64,
    calib_sum: Vector3<f64>,
    calibrating: bool,
    gyro_bias: Vector3<f64>,
    gyro_lpf: Iir,
    acc_lpf: Iir,
    acc_bias: Vector3<f64>,
    mag_bias: Vector3<f64>,
    mag_scale: Vector3<f64>,
    mag_threshold: f64,
    mag_outlier_max: u32,
    mag_outlier_count: u32,
    mag_filtering: bool,
    mag: Vector3<f64>,
}

impl ImuPreprocessor {
    /// A preprocessor that starts with gyro calibration (if the window is non-empty).
    pub fn new(config: &EstimatorConfig) -> Self {
        let calib_samples = config.gyro_calib_samples();
        Self {
            calib_samples,
            calib_count: 0,
            calib_sum: Vector3::zeros(),
            calibrating: calib_samples > 0,
            gyro_bias: Vector3::zeros(),
            gyro_lpf: Iir::new(config.gyro_lpf_factor),
            acc_lpf: Iir::new(config.acc_lpf_factor),
            acc_bias: Vector3::from(config.acc_bias),
            mag_bias: Vector3::from(config.mag_bias),
            mag_scale: Vector3::from(config.mag_scale),
            mag_threshold: config.mag_outlier_threshold,
            mag_outlier_max: config.mag_outlier_max_count,
            mag_outlier_count: 0,
            mag_filtering: false,
            mag: Vector3::zeros(),
        }
    }

    /// Whether the gyro bias is still being measured.
    pub fn calibrating(&self) -> bool {
        self.calibrating
    }

    /// The gyro bias in use (zero until calibration ends).
    pub fn gyro_bias(&self) -> Vector3<f64> {
        self.gyro_bias
    }

    /// Restarts the gyro calibration (firmware `gyroCalib(true, duration)`), keeping filters.
    pub fn restart_gyro_calibration(&mut self) {
        self.gyro_bias = Vector3::zeros();
        self.calib_sum = Vector3::zeros();
        self.calib_count = 0;
        self.calibrating = self.calib_samples > 0;
    }

    /// Processes one raw sample. Inputs must be finite (checked by the caller).
    pub fn step(
        &mut self,
        raw_gyro: &Vector3<f64>,
        raw_acc: &Vector3<f64>,
        raw_mag: &Vector3<f64>,
    ) -> FilteredImu {
        // Gyro: while calibrating, the raw value (bias not yet known) feeds the filter; the
        // sample that completes the window is still unbiased, as in the firmware.
        let mut gyro = *raw_gyro;
        if self.calibrating {
            self.calib_sum += raw_gyro;
            self.calib_count += 1;
            if self.calib_count >= self.calib_samples {
                self.gyro_bias = self.calib_sum / self.calib_count as f64;
                self.calibrating = false;
            }
        } else {
            gyro -= self.gyro_bias;
        }
        let gyro = self.gyro_lpf.step(&gyro);

        let acc = self.acc_lpf.step(&(raw_acc - self.acc_bias));

        let calibrated_mag = (raw_mag - self.mag_bias).component_mul(&self.mag_scale);
        if self.mag_filtering {
            let outlier =
                (0..3).any(|i| (calibrated_mag[i] - self.mag[i]).abs() > self.mag_threshold);
            if !outlier {
                self.mag = calibrated_mag;
                self.mag_outlier_count = 0;
            } else {
                self.mag_outlier_count = self.mag_outlier_count.saturating_add(1);
                if self.mag_outlier_count > self.mag_outlier_max {
                    self.mag_outlier_count = 0;
                    self.mag = calibrated_mag;
                }
            }
        } else if *raw_mag != Vector3::zeros() {
            // The driver reads zeros until the magnetometer is up; the first real sample is
            // taken as is and starts the outlier filter.
            self.mag = calibrated_mag;
            self.mag_filtering = true;
        }

        FilteredImu {
            gyro,
            acc,
            mag: self.mag,
        }
    }
}
