//! The Spinal mirror's step: attitude estimator, attitude controller and PWM conversion.

use super::config::AttitudeControlConfig;
use super::controller::{AttitudeController, AttitudeOutput};
use crate::estimate::{
    AttitudeEstimate, AttitudeEstimator, EstimateStatus, EstimatorConfig, EstimatorConfigError,
    ImuSample,
};

/// Parameters of [`SpinalStep`]. Both parts should use the same rate.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SpinalConfig {
    /// Estimator parameters.
    pub estimator: EstimatorConfig,
    /// Controller parameters.
    pub control: AttitudeControlConfig,
}

impl SpinalConfig {
    /// Firmware-exact parameters (per-sample factors, no anti-windup) at `rate_hz`.
    pub fn firmware(rate_hz: f64) -> Self {
        Self {
            estimator: EstimatorConfig::firmware(rate_hz),
            control: AttitudeControlConfig::firmware(rate_hz),
        }
    }

    /// Checks both parts and that their rates agree; names the field at fault.
    pub fn validate(&self) -> Result<(), &'static str> {
        self.estimator
            .validate()
            .map_err(|e: EstimatorConfigError| e.field)?;
        self.control.validate()?;
        if self.estimator.rate_hz != self.control.rate_hz {
            return Err("control.rate_hz (differs from estimator.rate_hz)");
        }
        Ok(())
    }
}

/// Result of one Spinal step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpinalOutput {
    /// Estimator status of this sample.
    pub estimate_status: EstimateStatus,
    /// The attitude estimate the controller used (the previous one if this sample was
    /// invalid).
    pub estimate: AttitudeEstimate,
    /// Controller output.
    pub control: AttitudeOutput,
}

/// Estimator + attitude controller + PWM conversion, one call per IMU sample.
#[derive(Clone, Debug)]
pub struct SpinalStep {
    estimator: AttitudeEstimator,
    controller: AttitudeController,
}

impl SpinalStep {
    /// A Spinal step for checked parameters.
    pub fn new(config: SpinalConfig) -> Result<Self, &'static str> {
        config.validate()?;
        Ok(Self {
            estimator: AttitudeEstimator::new(config.estimator).map_err(|e| e.field)?,
            controller: AttitudeController::new(config.control)?,
        })
    }

    /// The estimator.
    pub fn estimator(&self) -> &AttitudeEstimator {
        &self.estimator
    }

    /// The estimator, for calibration commands.
    pub fn estimator_mut(&mut self) -> &mut AttitudeEstimator {
        &mut self.estimator
    }

    /// The controller.
    pub fn controller(&self) -> &AttitudeController {
        &self.controller
    }

    /// The controller, to deliver messages (commands, gains, PWM info).
    pub fn controller_mut(&mut self) -> &mut AttitudeController {
        &mut self.controller
    }

    /// One step at `now_s` with a raw IMU sample and the battery voltage. Allocation-free.
    /// An invalid IMU sample is dropped by the estimator and the controller runs on the
    /// previous estimate (the firmware's controller always runs on the latest estimate).
    pub fn step(&mut self, now_s: f64, imu: &ImuSample, voltage: f64) -> SpinalOutput {
        let estimate_status = self.estimator.step(imu);
        let estimate = *self.estimator.estimate();
        let control = self.controller.step(
            now_s,
            &estimate.rotation,
            &estimate.angular_velocity,
            voltage,
        );
        SpinalOutput {
            estimate_status,
            estimate,
            control,
        }
    }
}
