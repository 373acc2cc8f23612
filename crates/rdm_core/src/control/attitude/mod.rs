//! The Spinal-side attitude step as the firmware splits it (`jsk-wire-protocols.md`
//! sec. 3.4-3.7): the roll/pitch part of the LQI law of eqs. (28)-(29) with per-rotor gains
//! from the PC, the saturation handling, the thrust -> PWM conversion, and the arming and
//! fail-safe state machine. [`SpinalStep`] chains the estimator and this controller into the
//! Spinal mirror's 200 Hz step.

mod config;
mod controller;
mod events;
mod spinal_step;
pub mod wire;

pub use config::{AntiWindup, AttitudeControlConfig, FIRMWARE_FORCE_LANDING_STEP};
pub use controller::{
    AttitudeController, AttitudeOutput, ControlCounters, ControlStatus, RotorAxisGains,
    UAV_MODEL_DRAGON,
};
pub use events::{CommandError, EventList, FlightConfigCmd, SpinalEvent};
pub use spinal_step::{SpinalConfig, SpinalOutput, SpinalStep};
