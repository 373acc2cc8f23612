//! The estimator's guards (not in the firmware; docs/spinal.md "Estimator guards").
//!
//! The firmware's filter has two ways to be poisoned by finite input:
//! - the first-order rotation `v += v x (w dt)` multiplies |v| by `sqrt(1 + |w_perp dt|^2)`
//!   each step, so a fast spin (34.9 rad/s at 200 Hz: x1.015 per step, e^15 over 5 s) makes
//!   the gravity vector so long that the accelerometer correction `(600 g + a)/601` no longer
//!   moves it, and a huge rate overflows it to inf, then NaN, for good;
//! - the integration error of that rotation leaves a wrong direction that the correction
//!   removes only at its slow rate (time constant 601 x 3 samples = 9 s at 200 Hz).
//!
//! With guards: samples beyond the sensor's range are dropped; after the gyro rotation a
//! vector longer than its bound is scaled back (direction kept) and a non-finite one is
//! re-initialised from the next sensor sample; a valid accelerometer sample that differs
//! from the gravity estimate by more than `degraded_angle_rad` makes the status `Degraded`,
//! and by more than `reinit_angle_rad` for `reinit_hold_s` re-initialises the gravity
//! estimate from it. The status is also `Degraded` while the error the gyro path itself
//! makes exceeds `degraded_angle_rad`:
//! - the gyro filter's delay: the IIR `p -= p/N; p += x; out = p/N` has summed
//!   `(N - 1)/N p` more rotation into its state than it has passed on, so the estimate lags
//!   the body by `(N - 1) dt |w_filtered|` (55 ms x |w| with the firmware's N = 12 at
//!   200 Hz: 20 deg at 6.3 rad/s);
//! - plus, since the last valid accelerometer sample (a fast spin makes the filtered
//!   accelerometer invalid), the first-order step's error `sum(theta - atan(theta))`,
//!   `theta = |w dt|` (the step turns a vector by `atan(theta)` instead of `theta`): about
//!   1 s at 34.9 rad/s and 200 Hz, hours at the rates of flight.
//!
//! Inside the sensor range and with agreeing vectors nothing changes: the firmware's
//! arithmetic runs untouched.

use nalgebra::Vector3;

use super::config::{EstimatorConfig, EstimatorGuards};
use super::imu_preprocess::FilteredImu;
use super::{AttitudeEstimator, ImuSample};

/// Bound of |gravity vector| as a multiple of the largest valid accelerometer norm.
///
/// ASSUMPTION: the gravity vector converges to the valid accelerometer's norm (at most
/// `sqrt(acc_norm_sq_max)` = 11.5 m/s^2); twice that can only come from the rotation's growth.
/// It is scaled back to `sqrt(acc_norm_sq_max)`.
const GRAVITY_BOUND: f64 = 2.0;
/// Bound of |heading vector| as a multiple of the larger of |magnetometer| and
/// |initial_heading| (looser: the magnetometer's norm may change after an accepted jump).
const HEADING_BOUND: f64 = 8.0;

/// State of the guards between steps.
#[derive(Clone, Copy, Debug)]
pub(super) struct GuardState {
    /// The last valid accelerometer sample differed from the gravity estimate by more than
    /// `degraded_angle_rad` (held until the next valid sample).
    disagrees: bool,
    /// Error bound of the gyro rotation since the last valid accelerometer sample, rad.
    unverified_rad: f64,
    /// The estimate's lag behind the body from the gyro filter's delay, rad.
    lag_rad: f64,
    degraded_angle_rad: f64,
    /// The gravity vector is to be re-initialised from the next valid accelerometer sample.
    gravity_pending: bool,
    /// The heading vector is to be re-initialised from the next magnetometer sample.
    pub(super) heading_pending: bool,
    /// Consecutive valid accelerometer samples beyond `reinit_angle_rad`.
    disagreeing: u64,
    /// Samples in `reinit_hold_s` (at least 1).
    hold_samples: u64,
    cos_degraded: f64,
    cos_reinit: f64,
}

impl GuardState {
    pub(super) fn new(config: &EstimatorConfig) -> Self {
        let guards = config.guards.unwrap_or_default();
        let hold = (guards.reinit_hold_s * config.rate_hz).ceil();
        Self {
            disagrees: false,
            unverified_rad: 0.0,
            lag_rad: 0.0,
            degraded_angle_rad: guards.degraded_angle_rad,
            gravity_pending: false,
            heading_pending: false,
            disagreeing: 0,
            hold_samples: if hold >= 1.0 { hold as u64 } else { 1 },
            cos_degraded: guards.degraded_angle_rad.cos(),
            cos_reinit: guards.reinit_angle_rad.cos(),
        }
    }
}

impl GuardState {
    /// Whether the estimate is degraded: a gross disagreement with the last valid
    /// accelerometer sample, or too large an error of the gyro path (delay plus unverified
    /// rotation since that sample).
    pub(super) fn degraded(&self) -> bool {
        self.disagrees || self.unverified_rad + self.lag_rad > self.degraded_angle_rad
    }

    /// One step of the gyro path: the rotation `theta = |w dt|` adds its error bound
    /// `theta - atan(theta)`; `lag_rad` is the filter delay's angle `(N - 1) theta`.
    pub(super) fn add_rotation(&mut self, theta: f64, gyro_lpf_factor: f64) {
        self.unverified_rad += theta - theta.atan();
        self.lag_rad = (gyro_lpf_factor - 1.0) * theta;
    }
}

/// Whether every gyro and accelerometer axis is inside the guard's range (the magnetometer
/// has no range check: its scale differs between boards).
pub(super) fn in_range(sample: &ImuSample, guards: &EstimatorGuards) -> bool {
    sample.gyro.iter().all(|v| v.abs() <= guards.gyro_range)
        && sample.acc.iter().all(|v| v.abs() <= guards.acc_range)
}

impl AttitudeEstimator {
    /// After the gyro rotation: a vector beyond its bound is scaled back to it, a non-finite
    /// one is cleared and marked for re-initialisation from the next sensor sample.
    pub(super) fn bound_vectors(&mut self, imu: &FilteredImu) {
        let g_norm_sq = self.est_g.norm_squared();
        let g_top_sq = self.config.acc_norm_sq_max;
        if !g_norm_sq.is_finite() {
            self.est_g = Vector3::zeros();
            self.guard.gravity_pending = true;
        } else if g_norm_sq > GRAVITY_BOUND * GRAVITY_BOUND * g_top_sq {
            self.est_g *= (g_top_sq / g_norm_sq).sqrt();
            self.counters.rescaled_vectors += 1;
        }
        let m_norm_sq = self.est_m.norm_squared();
        let m_ref_sq = imu
            .mag
            .norm_squared()
            .max(Vector3::from(self.config.initial_heading).norm_squared());
        if !m_norm_sq.is_finite() {
            self.est_m = Vector3::from(self.config.initial_heading);
            self.guard.heading_pending = true;
        } else if m_ref_sq > 0.0 && m_norm_sq > HEADING_BOUND * HEADING_BOUND * m_ref_sq {
            self.est_m *= (m_ref_sq / m_norm_sq).sqrt();
            self.counters.rescaled_vectors += 1;
        }
    }

    /// On a valid accelerometer sample: re-initialises a pending gravity vector, updates the
    /// degraded flag and re-initialises the gravity vector after a lasting gross
    /// disagreement. Returns whether the gravity vector was re-initialised (the firmware's
    /// correction then skips this sample).
    pub(super) fn check_gravity(&mut self, acc: &Vector3<f64>) -> bool {
        self.guard.unverified_rad = 0.0;
        if self.guard.gravity_pending {
            self.guard.gravity_pending = false;
            return self.reinitialise_gravity(acc);
        }
        let g_norm_sq = self.est_g.norm_squared();
        if g_norm_sq == 0.0 {
            // The firmware's start: the first correction sets the direction exactly.
            self.guard.disagrees = false;
            return false;
        }
        // cos(angle) < cos(threshold) <=> angle > threshold.
        let scale = (g_norm_sq * acc.norm_squared()).sqrt();
        let dot = self.est_g.dot(acc);
        self.guard.disagrees = dot < self.guard.cos_degraded * scale;
        if dot < self.guard.cos_reinit * scale {
            self.guard.disagreeing += 1;
            if self.guard.disagreeing >= self.guard.hold_samples {
                return self.reinitialise_gravity(acc);
            }
        } else {
            self.guard.disagreeing = 0;
        }
        false
    }

    fn reinitialise_gravity(&mut self, acc: &Vector3<f64>) -> bool {
        self.est_g = *acc;
        self.guard.disagreeing = 0;
        self.counters.reinitialisations += 1;
        true
    }
}
