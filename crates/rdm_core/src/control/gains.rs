//! The gain set that links the PC-side LQI synthesis to the Spinal-side attitude step
//! (`jsk-wire-protocols.md` sec. 3.4 and 4).

use crate::MAX_ROTORS;

/// Proportional, integral and derivative gain of one axis.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PidGains {
    pub p: f64,
    pub i: f64,
    pub d: f64,
}

/// Gains of one rotor: how its thrust reacts to the roll, pitch, yaw and altitude errors.
///
/// Spinal applies `roll`, `pitch` and `yaw.d` (carried by `rpy/gain`, int16 x 1000);
/// the PC applies `z` and `yaw.p`/`yaw.i` itself (sec. 4 "Gains sent to Spinal").
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RotorGains {
    pub roll: PidGains,
    pub pitch: PidGains,
    pub yaw: PidGains,
    pub z: PidGains,
}

/// One [`RotorGains`] per rotor, in rotor order; entries past the rotor count are zero.
pub type GainSet = [RotorGains; MAX_ROTORS];
