"""The Spinal-side attitude step: controller, flight state machine and the combined step.

* :class:`AttitudeController` applies the roll/pitch part of the LQI law (paper eqs. 28-29)
  with per-rotor gains from the PC, the gyro-moment compensation, yaw spreading, the
  saturation factors alpha/beta, thrust -> PWM, and the firmware's arming and fail-safe
  state machine (ARM_ON/OFF, FORCE_LANDING, 500 ms command timeout, 1 rad tilt limit).
* :class:`SpinalStep` chains the attitude estimator and the controller: the Spinal mirror's
  200 Hz step.
* Gain sets are float arrays of shape ``(rotors, 4, 3)`` (rotor, axis roll/pitch/yaw/z,
  term P/I/D); their ``rpy/gain`` wire form is int16 ``(rotors, 7)`` x 1000. The rotor
  count is the robot's, at most ``MAX_ROTORS`` (8); a controller drives ``motor_outputs``
  ESCs (its per-rotor outputs have that length).

Every method takes the caller's timestamp; nothing reads a clock. Rejected messages raise
:class:`CommandRejectedError` (a :class:`rdm._rdm.RdmError`) and are counted. Guards the
firmware lacks are on by default (battery-voltage window, command thrust saturation, the
estimator's range checks and recovery); ``firmware_exact=True`` selects the firmware's
behaviour for bit-exact comparison. No duty ever exceeds ``max_pwm`` and a non-finite thrust
gives ``min_duty``, in every configuration.
See ``docs/spinal.md``.
"""

from __future__ import annotations

from rdm._rdm import (
    MAX_ROTORS,
    AttitudeController,
    CommandRejectedError,
    ControlOutput,
    SpinalStep,
    SpinalStepOutput,
    clamp_gain,
    gains_from_wire_terms,
    gains_to_wire_terms,
)

#: ``spinal/FlightConfigCmd`` values.
ARM_ON = 0
ARM_OFF = 1
FORCE_LANDING = 2
INTEGRATION_CONTROL_ON = 160
INTEGRATION_CONTROL_OFF = 161

#: ``spinal/UavInfo`` models.
UAV_DRONE = 0
UAV_HYDRUS = 16
UAV_HYDRUS_XI = 17
UAV_DRAGON = 32

__all__ = [
    "ARM_OFF",
    "ARM_ON",
    "FORCE_LANDING",
    "INTEGRATION_CONTROL_OFF",
    "INTEGRATION_CONTROL_ON",
    "MAX_ROTORS",
    "UAV_DRAGON",
    "UAV_DRONE",
    "UAV_HYDRUS",
    "UAV_HYDRUS_XI",
    "AttitudeController",
    "CommandRejectedError",
    "ControlOutput",
    "SpinalStep",
    "SpinalStepOutput",
    "clamp_gain",
    "gains_from_wire_terms",
    "gains_to_wire_terms",
]
