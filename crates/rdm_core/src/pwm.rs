//! Thrust to PWM conversion as the Spinal firmware performs it.
