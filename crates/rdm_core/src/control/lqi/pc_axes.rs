//! The part of the LQI law the PC applies itself (sec. 4): altitude P-I-D into
//! `base_thrust[i]` and yaw P-I into `angles[2]`. Spinal applies roll, pitch and yaw D.

use super::gain_map::max_yaw_gain_index;
use super::gyro::RotorVector;
use super::LqiError;
use crate::control::gains::GainSet;

/// Errors of the PC-side axes (target minus estimate).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PcAxisErrors {
    /// `z_d − z` [m].
    pub z: f64,
    /// `ż_d − ż` [m/s].
    pub z_rate: f64,
    /// `ψ_d − ψ` [rad], wrapped to (−π, π] by the caller.
    pub yaw: f64,
}

/// What the PC sends in `FourAxisCommand`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PcAxisCommand {
    /// `base_thrust[i] = z.p e_z + z.i ∫e_z + z.d ė_z + feed_forward[i]`.
    pub base_thrust: RotorVector,
    /// `angles[2]`: yaw P-I of the rotor with the largest positive yaw D gain
    /// (0 when no rotor has one). Spinal spreads it in proportion to the yaw D gains.
    pub yaw_command: f64,
    /// The rotor whose yaw gains produced `yaw_command`.
    pub yaw_rotor: Option<usize>,
}

/// Integrators of the PC-side altitude and yaw loops.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PcAxisController {
    z_integral: f64,
    yaw_integral: f64,
}

impl PcAxisController {
    /// Fresh integrators.
    pub fn new() -> Self {
        Self::default()
    }

    /// `∫e_z` and `∫e_ψ`.
    pub fn integrals(&self) -> (f64, f64) {
        (self.z_integral, self.yaw_integral)
    }

    /// Zeroes the integrators (e.g. on take-off).
    pub fn reset(&mut self) {
        *self = Self::default();
    }

    /// Integrates the errors over `dt` (rectangle rule, first) and forms the command.
    /// Bad input leaves the integrators untouched.
    pub fn step(
        &mut self,
        gains: &GainSet,
        errors: &PcAxisErrors,
        feed_forward: &RotorVector,
        dt: f64,
    ) -> Result<PcAxisCommand, LqiError> {
        if !(dt.is_finite() && dt > 0.0) {
            return Err(LqiError::InvalidInput { argument: "dt" });
        }
        if ![errors.z, errors.z_rate, errors.yaw]
            .iter()
            .all(|v| v.is_finite())
        {
            return Err(LqiError::InvalidInput { argument: "errors" });
        }
        if feed_forward.iter().any(|v| !v.is_finite()) {
            return Err(LqiError::InvalidInput {
                argument: "feed_forward",
            });
        }
        self.z_integral += errors.z * dt;
        self.yaw_integral += errors.yaw * dt;
        let mut base_thrust = *feed_forward;
        for (rotor, g) in gains.iter().enumerate() {
            base_thrust[rotor] +=
                g.z.p * errors.z + g.z.i * self.z_integral + g.z.d * errors.z_rate;
        }
        let yaw_rotor = max_yaw_gain_index(gains);
        let yaw_command = yaw_rotor.map_or(0.0, |rotor| {
            let yaw = gains[rotor].yaw;
            yaw.p * errors.yaw + yaw.i * self.yaw_integral
        });
        Ok(PcAxisCommand {
            base_thrust,
            yaw_command,
            yaw_rotor,
        })
    }
}
