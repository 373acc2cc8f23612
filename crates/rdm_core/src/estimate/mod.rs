//! Attitude estimation as the Spinal firmware runs it: IMU preprocessing plus the
//! gravity/magnetic-vector complementary filter (`jsk-wire-protocols.md` sec. 3.2-3.3).
//!
//! The estimate feeds the Spinal-side attitude step ([`crate::control::attitude`]), which
//! applies the roll/pitch part of the LQI law of eqs. (28)-(29).
//!
//! [`EstimatorGuards`] (the default; `guards: None` is firmware-exact) add what the firmware
//! lacks: samples outside the sensor's range are rejected, the filter vectors are kept
//! bounded and re-initialised when they degenerate or disagree grossly with a valid
//! accelerometer, and the status says when the estimate is degraded (`guard.rs`).

mod config;
mod guard;
mod imu_preprocess;

pub use config::{
    EstimatorConfig, EstimatorConfigError, EstimatorGuards, ACC_FULL_SCALE, FIRMWARE_RATE_HZ,
    GYRO_FULL_SCALE, MAX_SENSOR_RANGE,
};
pub use imu_preprocess::{FilteredImu, ImuPreprocessor};

use guard::GuardState;

use nalgebra::{Matrix3, Vector3};

/// One raw IMU sample in the body frame.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ImuSample {
    /// Angular velocity, rad/s.
    pub gyro: [f64; 3],
    /// Specific force, m/s^2 (reads +g upward at rest).
    pub acc: [f64; 3],
    /// Magnetic field in the driver's units (about uT); all zeros means "no sample yet".
    /// A value equal to the previous accepted one is not fused again (the firmware fuses
    /// the magnetometer only when its value changed).
    pub mag: [f64; 3],
}

/// Outcome of one estimator step.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EstimateStatus {
    /// Estimate updated.
    Ok,
    /// Estimate updated, but the gyro bias window is still open (bias not subtracted yet).
    Calibrating,
    /// Estimate updated, but the gravity or heading vector is degenerate (for example no
    /// magnetometer sample yet): the rotation is the identity, as the firmware's NaN rule.
    AttitudeUndefined,
    /// Estimate updated, but it may be wrong by more than `degraded_angle_rad` (guards
    /// only): the gravity estimate differs from the last valid accelerometer sample by more
    /// than that (while the filter re-converges), or the gyro path's error bound exceeds it
    /// (the gyro filter's delay `(N - 1) dt |w|` plus the first-order rotation's error since
    /// that sample: a fast spin).
    Degraded,
    /// A NaN or infinite input, or (guards on) a sample outside the sensor's range; the
    /// sample was dropped and the state left untouched.
    InvalidInput,
}

/// The attitude estimate after a step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AttitudeEstimate {
    /// Body attitude in the world frame; rows are the world axes (x_b, y_b, z_b) seen in the
    /// body frame, so `v_world = rotation * v_body`.
    pub rotation: Matrix3<f64>,
    /// The same rotation as a unit quaternion, order x, y, z, w, with w >= 0.
    pub quaternion: [f64; 4],
    /// Roll, pitch, yaw of `rotation`, ArduPilot ZYX convention, rad.
    pub euler: [f64; 3],
    /// Filtered, bias-corrected angular velocity, rad/s ("angular velocity" output).
    pub angular_velocity: Vector3<f64>,
    /// Filtered specific force, m/s^2.
    pub acc: Vector3<f64>,
    /// Magnetometer value after calibration and outlier rejection.
    pub mag: Vector3<f64>,
}

impl Default for AttitudeEstimate {
    fn default() -> Self {
        Self {
            rotation: Matrix3::identity(),
            quaternion: [0.0, 0.0, 0.0, 1.0],
            euler: [0.0; 3],
            angular_velocity: Vector3::zeros(),
            acc: Vector3::zeros(),
            mag: Vector3::zeros(),
        }
    }
}

/// Counters of an estimator.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct EstimatorCounters {
    /// Steps taken (accepted samples).
    pub steps: u64,
    /// Samples dropped for NaN/inf.
    pub invalid_inputs: u64,
    /// Samples dropped for a gyro or accelerometer axis outside the guard's range.
    pub out_of_range: u64,
    /// Filter vectors scaled back to their bound (guards only).
    pub rescaled_vectors: u64,
    /// Gravity or heading vectors re-initialised from a sensor sample (guards only).
    pub reinitialisations: u64,
    /// Steps reported `Degraded`.
    pub degraded_steps: u64,
    /// Accelerometer corrections applied.
    pub acc_corrections: u64,
    /// Magnetometer corrections applied.
    pub mag_corrections: u64,
    /// Steps whose rotation fell back to the identity.
    pub undefined_attitudes: u64,
}

/// The Spinal complementary-filter attitude estimator.
#[derive(Clone, Debug)]
pub struct AttitudeEstimator {
    config: EstimatorConfig,
    dt: f64,
    imu: ImuPreprocessor,
    est_g: Vector3<f64>,
    est_m: Vector3<f64>,
    prev_mag: Vector3<f64>,
    acc_count: u32,
    guard: GuardState,
    estimate: AttitudeEstimate,
    counters: EstimatorCounters,
}

impl AttitudeEstimator {
    /// An estimator for a checked configuration.
    pub fn new(config: EstimatorConfig) -> Result<Self, EstimatorConfigError> {
        config.validate()?;
        Ok(Self {
            dt: config.dt(),
            imu: ImuPreprocessor::new(&config),
            est_g: Vector3::zeros(),
            est_m: Vector3::from(config.initial_heading),
            prev_mag: Vector3::zeros(),
            acc_count: 0,
            guard: GuardState::new(&config),
            estimate: AttitudeEstimate::default(),
            counters: EstimatorCounters::default(),
            config,
        })
    }

    /// The configuration in use.
    pub fn config(&self) -> &EstimatorConfig {
        &self.config
    }

    /// The latest estimate.
    pub fn estimate(&self) -> &AttitudeEstimate {
        &self.estimate
    }

    /// Counters since construction.
    pub fn counters(&self) -> &EstimatorCounters {
        &self.counters
    }

    /// The gyro bias in use.
    pub fn gyro_bias(&self) -> Vector3<f64> {
        self.imu.gyro_bias()
    }

    /// Estimated gravity direction vector in the body frame (unnormalised filter state).
    pub fn gravity_vector(&self) -> Vector3<f64> {
        self.est_g
    }

    /// Estimated magnetic vector in the body frame (unnormalised filter state).
    pub fn heading_vector(&self) -> Vector3<f64> {
        self.est_m
    }

    /// Restarts the gyro bias calibration window.
    pub fn restart_gyro_calibration(&mut self) {
        self.imu.restart_gyro_calibration();
    }

    /// Whether the estimate is degraded (guards only; see [`EstimateStatus::Degraded`]).
    pub fn degraded(&self) -> bool {
        self.config.guards.is_some() && self.guard.degraded()
    }

    /// Processes one sample. Allocation-free; never panics; a non-finite input (or, guards
    /// on, an out-of-range one) is dropped.
    pub fn step(&mut self, sample: &ImuSample) -> EstimateStatus {
        let all_finite = sample
            .gyro
            .iter()
            .chain(sample.acc.iter())
            .chain(sample.mag.iter())
            .all(|v| v.is_finite());
        if !all_finite {
            self.counters.invalid_inputs += 1;
            return EstimateStatus::InvalidInput;
        }
        if let Some(guards) = &self.config.guards {
            if !guard::in_range(sample, guards) {
                self.counters.out_of_range += 1;
                return EstimateStatus::InvalidInput;
            }
        }
        self.counters.steps += 1;

        let imu = self.imu.step(
            &Vector3::from(sample.gyro),
            &Vector3::from(sample.acc),
            &Vector3::from(sample.mag),
        );

        // 1. Rotate both world-fixed vectors by the gyro: v += v x (w dt).
        let rotation_step = imu.gyro * self.dt;
        let g_before = self.est_g;
        let m_before = self.est_m;
        self.est_m += m_before.cross(&rotation_step);
        self.est_g += g_before.cross(&rotation_step);
        let guarded = self.config.guards.is_some();
        if guarded {
            self.guard
                .add_rotation(rotation_step.norm(), self.config.gyro_lpf_factor);
            self.bound_vectors(&imu);
        }

        // 2. Gravity correction on every n-th valid accelerometer sample.
        let acc_norm_sq = imu.acc.norm_squared();
        let acc_valid =
            self.config.acc_norm_sq_min < acc_norm_sq && acc_norm_sq < self.config.acc_norm_sq_max;
        let reinitialised = guarded && acc_valid && self.check_gravity(&imu.acc);
        if acc_valid && self.acc_count == 0 && !reinitialised {
            let k = self.config.acc_cmpf_factor;
            self.est_g = (self.est_g * k + imu.acc) * (1.0 / (k + 1.0));
            self.counters.acc_corrections += 1;
        }

        // 3. Magnetic correction when the magnetometer value changed.
        if guarded && self.guard.heading_pending && imu.mag != Vector3::zeros() {
            self.est_m = imu.mag;
            self.prev_mag = imu.mag;
            self.guard.heading_pending = false;
            self.counters.reinitialisations += 1;
        }
        if self.prev_mag != imu.mag {
            self.prev_mag = imu.mag;
            let k = self.config.mag_cmpf_factor;
            self.est_m = (self.est_m * k + imu.mag) * (1.0 / (k + 1.0));
            self.counters.mag_corrections += 1;
        }
        if acc_valid {
            self.acc_count += 1;
            if self.acc_count >= self.config.acc_prescaler {
                self.acc_count = 0;
            }
        }

        // 4. Attitude from the two vectors; NaN (degenerate vectors) -> identity.
        let (rotation, defined) = match attitude_from_vectors(&self.est_g, &self.est_m) {
            Some(r) => (r, true),
            None => (Matrix3::identity(), false),
        };
        if !defined {
            self.counters.undefined_attitudes += 1;
        }
        self.estimate = AttitudeEstimate {
            rotation,
            quaternion: quaternion_xyzw(&rotation),
            euler: euler_zyx(&rotation),
            angular_velocity: imu.gyro,
            acc: imu.acc,
            mag: imu.mag,
        };

        if self.imu.calibrating() {
            EstimateStatus::Calibrating
        } else if !defined {
            EstimateStatus::AttitudeUndefined
        } else if guarded && self.guard.degraded() {
            self.counters.degraded_steps += 1;
            EstimateStatus::Degraded
        } else {
            EstimateStatus::Ok
        }
    }
}

/// The rotation with rows (x_b, y_b, z_b): `z_b = g/|g|`, `y_b = normalize(z_b x m)`,
/// `x_b = normalize(y_b x z_b)`. `None` when a vector is degenerate (the firmware's NaN).
pub fn attitude_from_vectors(g: &Vector3<f64>, m: &Vector3<f64>) -> Option<Matrix3<f64>> {
    let z = *g / g.norm();
    let y_raw = z.cross(m);
    let y = y_raw / y_raw.norm();
    let x_raw = y.cross(&z);
    let x = x_raw / x_raw.norm();
    let r = Matrix3::from_rows(&[x.transpose(), y.transpose(), z.transpose()]);
    r.iter().all(|v| v.is_finite()).then_some(r)
}

/// Roll, pitch, yaw of a rotation in the ArduPilot ZYX convention (`Matrix3::to_euler`):
/// roll = atan2(c.y, c.z), pitch = -asin(c.x), yaw = atan2(b.x, a.x), with a, b, c the rows.
pub fn euler_zyx(r: &Matrix3<f64>) -> [f64; 3] {
    let roll = r[(2, 1)].atan2(r[(2, 2)]);
    let pitch = -r[(2, 0)].clamp(-1.0, 1.0).asin();
    let yaw = r[(1, 0)].atan2(r[(0, 0)]);
    [roll, pitch, yaw]
}

/// The rotation `Rz(yaw) Ry(pitch) Rx(roll)` (ArduPilot `from_euler`).
pub fn rotation_from_euler(roll: f64, pitch: f64, yaw: f64) -> Matrix3<f64> {
    let (sr, cr) = roll.sin_cos();
    let (sp, cp) = pitch.sin_cos();
    let (sy, cy) = yaw.sin_cos();
    Matrix3::new(
        cp * cy,
        sr * sp * cy - cr * sy,
        cr * sp * cy + sr * sy,
        cp * sy,
        sr * sp * sy + cr * cy,
        cr * sp * sy - sr * cy,
        -sp,
        sr * cp,
        cr * cp,
    )
}

/// Unit quaternion (x, y, z, w) of a rotation matrix by Shepperd's method, w >= 0.
pub fn quaternion_xyzw(r: &Matrix3<f64>) -> [f64; 4] {
    let trace = r[(0, 0)] + r[(1, 1)] + r[(2, 2)];
    let mut q = if trace > 0.0 {
        let s = 2.0 * (trace + 1.0).sqrt();
        [
            (r[(2, 1)] - r[(1, 2)]) / s,
            (r[(0, 2)] - r[(2, 0)]) / s,
            (r[(1, 0)] - r[(0, 1)]) / s,
            0.25 * s,
        ]
    } else if r[(0, 0)] > r[(1, 1)] && r[(0, 0)] > r[(2, 2)] {
        let s = 2.0 * (1.0 + r[(0, 0)] - r[(1, 1)] - r[(2, 2)]).sqrt();
        [
            0.25 * s,
            (r[(0, 1)] + r[(1, 0)]) / s,
            (r[(0, 2)] + r[(2, 0)]) / s,
            (r[(2, 1)] - r[(1, 2)]) / s,
        ]
    } else if r[(1, 1)] > r[(2, 2)] {
        let s = 2.0 * (1.0 + r[(1, 1)] - r[(0, 0)] - r[(2, 2)]).sqrt();
        [
            (r[(0, 1)] + r[(1, 0)]) / s,
            0.25 * s,
            (r[(1, 2)] + r[(2, 1)]) / s,
            (r[(0, 2)] - r[(2, 0)]) / s,
        ]
    } else {
        let s = 2.0 * (1.0 + r[(2, 2)] - r[(0, 0)] - r[(1, 1)]).sqrt();
        [
            (r[(0, 2)] + r[(2, 0)]) / s,
            (r[(1, 2)] + r[(2, 1)]) / s,
            0.25 * s,
            (r[(1, 0)] - r[(0, 1)]) / s,
        ]
    };
    let norm = q.iter().map(|v| v * v).sum::<f64>().sqrt();
    let sign = if q[3] < 0.0 { -1.0 } else { 1.0 };
    if norm.is_finite() && norm > 0.0 {
        for v in &mut q {
            *v *= sign / norm;
        }
        q
    } else {
        [0.0, 0.0, 0.0, 1.0]
    }
}
