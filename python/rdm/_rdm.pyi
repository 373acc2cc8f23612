"""Type stubs of the compiled core :mod:`rdm._rdm` (see crates/rdm_py)."""

from typing import final as _final

from typing_extensions import Self as _Self

__all__ = [
    "GRAVITY",
    "JSK_TO_PAPER",
    "MAX_ROTORS",
    "MAX_TILT_RAD",
    "MAX_WIRE_GAIN",
    "N_VECTORING",
    "PERCH_ROTORS",
    "AttitudeController",
    "AttitudeEstimator",
    "CanMaster",
    "CanMasterError",
    "CanWire",
    "CareSolveError",
    "CommandRejectedError",
    "ContactGateCore",
    "ControlOutput",
    "CorePlanner",
    "DescriptionError",
    "FootTrackerCore",
    "ImuNoiseCore",
    "LeptrinoStreamCore",
    "LockstepKernel",
    "LqiSynthesisError",
    "LqiSynthesizer",
    "McapChunkBatch",
    "ModelError",
    "NeuronBank",
    "NeuronBankError",
    "NormalStreamCore",
    "PcAxisController",
    "PerchController",
    "PerchError",
    "PerchQp",
    "PlannerError",
    "PlantBridgeCore",
    "PlantStateCore",
    "PlantStepCore",
    "PlateContactCore",
    "PositionControlError",
    "PositionController",
    "PwmConverter",
    "QpInputError",
    "QpSolver",
    "RdmError",
    "RestingSleepCore",
    "Robot",
    "RosserialFrameError",
    "RotorPlantCore",
    "SampleSchedule",
    "SpinalMirrorState",
    "SpinalStep",
    "SpinalStepOutput",
    "StopFlag",
    "TickCounter",
    "WrenchFilter",
    "WrenchNoiseCore",
    "__version__",
    "augmented_system",
    "bench_build_profile",
    "capture_index_records",
    "clamp_gain",
    "duty_to_can",
    "duty_to_dshot",
    "duty_to_pwm_report",
    "finite_float_vector",
    "flight_axes",
    "flight_thrust",
    "gain_set_from_k",
    "gains_from_wire_terms",
    "gains_to_wire_terms",
    "gyro_compensation",
    "json_float_list",
    "json_record",
    "leptrino_ok_sample_run",
    "rosserial_frame",
    "rosserial_scan",
    "servo_target_payload",
    "solve_care",
    "spinal_apply_commands",
    "spinal_duty_list",
    "spinal_imu_frame",
    "spinal_servo_states_frame",
    "time_lqi_synthesis",
    "time_onboard_ticks",
    "time_spinal_steps",
    "time_timer_overhead",
    "vectoring_angles",
]

__version__: str

class RdmError(ValueError):
    """Base class of every error raised by rdm's core."""

# --- model ---
from collections.abc import Callable, Sequence
from os import PathLike
from typing import Any

import numpy as np
import numpy.typing as npt

_F = npt.NDArray[np.float64]
_Pose = _F | list[list[float]] | list[float] | None

class DescriptionError(RdmError):
    """A robot description is malformed or inconsistent; the message names file and field."""

class ModelError(RdmError):
    """Bad input to a model evaluation; the message names the argument."""

class Robot:
    """Robot description (URDF + TOML) with its evaluation workspace.

    Joint order of ``q``: the TOML's ``joint_order`` (shipped robots:
    q1..q6, alpha1, beta1, alpha2, beta2). ``base_pose`` is the pose of the root link (the
    foot) in the world: None (identity), a 4x4 matrix or [x, y, z, roll, pitch, yaw]
    (R = Rz(yaw) Ry(pitch) Rx(roll)).
    """

    def __new__(cls, urdf: str | PathLike[str], toml: str | PathLike[str]) -> _Self: ...
    @staticmethod
    def from_strs(
        urdf_text: str, toml_text: str, urdf_name: str = "<urdf>", toml_name: str = "<toml>"
    ) -> Robot: ...
    @property
    def name(self) -> str: ...
    @property
    def sources(self) -> tuple[str, str]: ...
    @property
    def joint_names(self) -> list[str]: ...
    @property
    def n_q(self) -> int: ...
    @property
    def n_rotors(self) -> int: ...
    @property
    def mass(self) -> float: ...
    @property
    def joint_limits(self) -> _F:
        """(n_q, 2) lower/upper position limits [rad]."""
    @property
    def stall_torques(self) -> _F: ...
    @property
    def link_names(self) -> list[str]: ...
    @property
    def rotor_names(self) -> list[str]: ...
    @property
    def frame_names(self) -> list[str]: ...
    @property
    def rotors(self) -> list[dict[str, Any]]:
        """name, parent, offset, axis, spin, drag_to_thrust, thrust_min, thrust_max, diameter."""
    @property
    def vectoring_units(self) -> list[dict[str, Any]]: ...
    @property
    def plate_size(self) -> tuple[float, float]: ...
    @property
    def friction(self) -> tuple[float, float]: ...
    @property
    def sensors(self) -> dict[str, dict[str, Any]]: ...
    def evaluate(self, q: npt.ArrayLike, base_pose: _Pose = None) -> dict[str, Any]:
        """Keys: mass, cog (world), inertia (about CoG, CoG frame), inertia_world,
        allocation (6 x N, CoG frame, eqs. 7-9), allocation_bar (4 x N), rotor_positions
        (N x 3), rotor_directions (N x 3), frames (name -> 4x4 world pose), foot_in_cog
        (4x4), unit_parent_rotations (list of 3x3, C<-L_i), aerial_zmp (2,), zmp_margin,
        zmp_inside, zmp_degenerate, rho (eq. 65)."""
    def evaluate_control(
        self, q: npt.ArrayLike, frame: str
    ) -> tuple[
        float,
        NDArray[np.float64],
        NDArray[np.float64],
        NDArray[np.float64],
        NDArray[np.float64],
        list[NDArray[np.float64]],
        NDArray[np.float64],
        NDArray[np.float64],
    ]:
        """What the onboard pipeline reads of ``evaluate(q)`` (the same arrays): mass,
        inertia, allocation, allocation_bar, foot_in_cog, unit_parent_rotations,
        frames["cog"], frames[frame]. Errors as ``evaluate``; ModelError for an unknown
        frame."""
    def aerial_zmp_from_thrusts(
        self, q: npt.ArrayLike, thrusts: npt.ArrayLike, base_pose: _Pose = None
    ) -> dict[str, Any] | None: ...
    def static_torques(
        self,
        q: npt.ArrayLike,
        thrusts: npt.ArrayLike,
        base_pose: _Pose = None,
        foot_wrench: npt.ArrayLike | None = None,
        end_effector_wrench: npt.ArrayLike | None = None,
        gravity: tuple[float, float, float] = ...,
    ) -> tuple[_F, _F]:
        """(tau of eq. 61 in q order, net external wrench about the base origin); ``gravity``
        defaults to (0, 0, -9.80665) m/s^2."""
    def jacobian(self, frame: str, zeta: npt.ArrayLike) -> _F:
        """6 x (6 + n_q) w.r.t. zeta = [p, roll, pitch, yaw, q]; rows: world linear, angular."""

# --- perch ---
from typing import Any as _Any

import numpy as _np
from numpy.typing import NDArray as _NDArray

class PerchError(RdmError):
    """Bad argument or parameter of the perching controller (the message names it)."""

@_final
class PerchQp:
    def __new__(cls, params: dict[str, _Any] | None = None) -> _Self: ...
    def solve(
        self,
        foot_allocation: _NDArray[_np.float64],
        allocation: _NDArray[_np.float64],
        mass: float,
        foot_wrench: _NDArray[_np.float64],
        previous_thrust: _NDArray[_np.float64],
        previous_foot_wrench: _NDArray[_np.float64],
        flight_thrust: _NDArray[_np.float64] | None = None,
    ) -> dict[str, _Any]: ...
    def problem_data(self) -> dict[str, _Any]: ...
    def counters(self) -> dict[str, int]: ...
    def params(self) -> dict[str, _Any]: ...

@_final
class PerchController:
    def __new__(
        cls, params: dict[str, _Any] | None = None, rate_hz: float = 40.0, cutoff_hz: float = 1.0
    ) -> _Self: ...
    def tick(
        self,
        foot_wrench: _NDArray[_np.float64],
        foot_allocation: _NDArray[_np.float64],
        allocation: _NDArray[_np.float64],
        mass: float,
        flight_thrust: _NDArray[_np.float64] | None = None,
    ) -> dict[str, _Any]: ...
    def reset(self, thrust: _NDArray[_np.float64] | None = None) -> None: ...
    def filtered_foot_wrench(self) -> _NDArray[_np.float64]: ...
    def filter_coefficients(self) -> tuple[float, float, float]: ...
    def problem_data(self) -> dict[str, _Any]: ...
    def counters(self) -> dict[str, int]: ...
    def params(self) -> dict[str, _Any]: ...

@_final
class WrenchFilter:
    def __new__(cls, cutoff_hz: float = 1.0, sample_hz: float = 40.0) -> _Self: ...
    def update(self, sample: _NDArray[_np.float64]) -> _NDArray[_np.float64] | None: ...
    def reset(self) -> None: ...
    def coefficients(self) -> tuple[float, float, float]: ...

# --- spinal ---

import numpy as np
import numpy.typing as npt

#: Capacity of the per-rotor storage of the real-time core (a robot has 1..MAX_ROTORS).
MAX_ROTORS: int
#: Rotors of the perching QP.
PERCH_ROTORS: int

class CommandRejectedError(RdmError):
    """A message to the Spinal controller was rejected or ignored; names the field."""

@_final
class AttitudeEstimator:
    """Spinal complementary-filter attitude estimator (docs/spinal.md)."""

    def __new__(
        cls,
        rate_hz: float = 200.0,
        time_matched: bool = False,
        *,
        firmware_exact: bool = False,
        **overrides: Any,
    ) -> _Self:
        """``overrides``: the EstimatorConfig fields and the guards' ``gyro_range``,
        ``acc_range``, ``degraded_angle_rad``, ``reinit_angle_rad``, ``reinit_hold_s``;
        ``firmware_exact=True`` has no guards."""
    def step(self, gyro: Any, acc: Any, mag: Any) -> str:
        """ "ok", "calibrating", "attitude_undefined", "degraded" or "invalid_input"."""
    def run(
        self,
        gyro: npt.NDArray[np.float64],
        acc: npt.NDArray[np.float64],
        mag: npt.NDArray[np.float64],
    ) -> dict[str, Any]: ...
    def restart_gyro_calibration(self) -> None: ...
    def estimate(self) -> dict[str, npt.NDArray[np.float64]]: ...
    @property
    def rotation(self) -> npt.NDArray[np.float64]: ...
    @property
    def quaternion(self) -> npt.NDArray[np.float64]: ...
    @property
    def euler(self) -> npt.NDArray[np.float64]: ...
    @property
    def angular_velocity(self) -> npt.NDArray[np.float64]: ...
    @property
    def acc(self) -> npt.NDArray[np.float64]: ...
    @property
    def mag(self) -> npt.NDArray[np.float64]: ...
    @property
    def gyro_bias(self) -> npt.NDArray[np.float64]: ...
    @property
    def filter_vectors(self) -> npt.NDArray[np.float64]: ...
    @property
    def counters(self) -> dict[str, int]: ...
    @property
    def degraded(self) -> bool: ...
    @property
    def config(self) -> dict[str, Any]: ...

@_final
class ControlOutput:
    """Output of one controller step."""

    @property
    def status(self) -> str: ...
    @property
    def thrust(self) -> npt.NDArray[np.float64]: ...
    @property
    def duty(self) -> npt.NDArray[np.float64]: ...
    @property
    def pwm_report(self) -> npt.NDArray[np.uint16]: ...
    @property
    def alpha(self) -> float: ...
    @property
    def beta(self) -> float: ...
    @property
    def euler(self) -> npt.NDArray[np.float64]: ...
    @property
    def error_integral(self) -> npt.NDArray[np.float64]: ...
    @property
    def events(self) -> list[tuple[str, Any]]:
        """Events since the previous step: ("ack", cmd), ("failsafe_timeout", None),
        ("failsafe_tilt", None), ("failsafe_command_tilt", None), ("rejected", message),
        ("voltage_rejected", None), ("command_saturated", None), ("non_finite_output", None),
        ("alpha_bounded", None); ("events_dropped", n) last when some were lost."""
        ...

@_final
class SpinalStepOutput:
    """Output of one SpinalStep.step."""

    @property
    def estimate_status(self) -> str: ...
    @property
    def control(self) -> ControlOutput: ...
    @property
    def status(self) -> str: ...
    @property
    def duty(self) -> npt.NDArray[np.float64]: ...
    @property
    def thrust(self) -> npt.NDArray[np.float64]: ...
    @property
    def euler(self) -> npt.NDArray[np.float64]: ...
    @property
    def quaternion(self) -> npt.NDArray[np.float64]: ...
    @property
    def angular_velocity(self) -> npt.NDArray[np.float64]: ...
    def estimate(self) -> dict[str, npt.NDArray[np.float64]]: ...
    @property
    def events(self) -> list[tuple[str, Any]]:
        """The control step's events (:attr:`ControlOutput.events`)."""
        ...

class _SpinalControllerMessages:
    def set_uav_info(self, motor_num: int, uav_model: int) -> None: ...
    def set_pwm_info(
        self,
        min_pwm: float,
        max_pwm: float,
        min_thrust: float,
        force_landing_thrust: float,
        mode: int,
        motor_info: npt.NDArray[np.float64],
    ) -> None: ...
    def set_pwm_info_hydrus_example(self) -> None: ...
    def flight_config(self, cmd: int, now_s: float) -> None: ...
    def four_axis_command(
        self, angles: Any, base_thrust: npt.NDArray[np.float64], now_s: float
    ) -> None: ...
    def set_gains(self, gains: npt.NDArray[np.float64]) -> None: ...
    def set_gains_wire(self, terms: npt.NDArray[np.int64]) -> None: ...
    def set_torque_allocation_inv_wire(self, rows: npt.NDArray[np.int16]) -> None: ...
    def set_pinv_inertia(self, pinv: npt.NDArray[np.float64], inertia: Any) -> None: ...
    def set_pinv_inertia_wire(self, pinv: npt.NDArray[np.int16], inertia: Any) -> None: ...
    def set_desire_coordinate(self, roll: float, pitch: float, yaw: float) -> None: ...
    def set_attitude_control(self, enabled: bool) -> None: ...
    def set_gains_wire_rows(self, rows: list[tuple[int, ...]]) -> None:
        """``set_gains_wire`` from rows of 7 ints (no array)."""
    def set_pinv_inertia_wire_rows(
        self, pinv: list[tuple[int, int, int]], inertia: list[int]
    ) -> None:
        """``set_pinv_inertia_wire`` from int rows (no array)."""
    def four_axis_command_list(
        self, angles: tuple[float, float, float], base_thrust: list[float], now_s: float
    ) -> None:
        """``four_axis_command`` from plain floats (no array)."""
    @property
    def armed(self) -> bool: ...
    @property
    def force_landing(self) -> bool: ...
    @property
    def integrating(self) -> bool: ...
    @property
    def motor_number(self) -> int: ...
    @property
    def base_thrust(self) -> npt.NDArray[np.float64]: ...
    @property
    def error_integral(self) -> npt.NDArray[np.float64]: ...
    @property
    def target_angles(self) -> npt.NDArray[np.float64]: ...
    @property
    def max_yaw_index(self) -> int | None: ...
    @property
    def thrust_gains(self) -> npt.NDArray[np.float64]: ...
    @property
    def pwm_state(self) -> tuple[float, float, float, int] | None: ...
    @property
    def voltage_window(self) -> tuple[float, float] | None: ...
    @property
    def last_good_voltage(self) -> float | None: ...
    @property
    def counters(self) -> dict[str, int]: ...

@_final
class AttitudeController(_SpinalControllerMessages):
    """Spinal attitude controller and flight state machine. ``firmware_exact=True`` selects
    the firmware-exact option of every guard; ``None`` booleans follow it."""

    def __new__(
        cls,
        rate_hz: float = 200.0,
        *,
        firmware_exact: bool = False,
        anti_windup: bool | None = None,
        integral_limit: float = 1.0,
        command_timeout_s: float = 0.5,
        max_tilt_rad: float = 1.0,
        force_landing_rate: float = 2.5,
        voltage_guard: bool | None = None,
        battery_cells: int = 0,
        cell_voltage_range: tuple[float, float] = ...,  # default (3.0, 4.45) V per cell
        saturate_commands: bool | None = None,
        bound_alpha: bool | None = None,
        motor_outputs: int = 4,
    ) -> _Self: ...
    def step(
        self, now_s: float, rotation: npt.NDArray[np.float64], gyro: Any, voltage: float
    ) -> ControlOutput: ...

@_final
class SpinalStep(_SpinalControllerMessages):
    """Estimator + attitude controller + PWM conversion (the Spinal mirror's step)."""

    def __new__(
        cls,
        rate_hz: float = 200.0,
        *,
        time_matched: bool = False,
        firmware_exact: bool = False,
        anti_windup: bool | None = None,
        integral_limit: float = 1.0,
        command_timeout_s: float = 0.5,
        max_tilt_rad: float = 1.0,
        force_landing_rate: float = 2.5,
        voltage_guard: bool | None = None,
        battery_cells: int = 0,
        cell_voltage_range: tuple[float, float] = ...,  # default (3.0, 4.45) V per cell
        saturate_commands: bool | None = None,
        bound_alpha: bool | None = None,
        motor_outputs: int = 4,
        **estimator_overrides: Any,
    ) -> _Self: ...
    def step(
        self, now_s: float, gyro: Any, acc: Any, mag: Any, voltage: float
    ) -> SpinalStepOutput: ...
    @property
    def steps(self) -> int:
        """Steps run since construction (``step`` and the lockstep kernel's steps)."""
    @property
    def estimator_counters(self) -> dict[str, int]: ...
    def restart_gyro_calibration(self) -> None: ...
    def calibration_data(self) -> list[float]:
        """GET_CALIB_DATA's 12 floats: gyro bias, accelerometer bias, magnetometer bias and
        scale."""
        ...

@_final
class PwmConverter:
    """Thrust -> duty conversion as Spinal's pwmConversion."""

    def __new__(
        cls,
        min_pwm: float,
        max_pwm: float,
        min_thrust: float,
        force_landing_thrust: float,
        mode: int,
        motor_info: npt.NDArray[np.float64],
        *,
        voltage_guard: bool = True,
        battery_cells: int = 0,
        cell_voltage_range: tuple[float, float] = ...,  # default (3.0, 4.45) V per cell
    ) -> _Self: ...
    def update_voltage(self, voltage: float, now_s: float) -> bool: ...
    def force_voltage(self, voltage: float) -> bool: ...
    def set_rotor_divider(self, rotor_divider: float) -> None: ...
    def raw_duty(self, thrust: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]: ...
    def duty(self, thrust: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]: ...
    @property
    def voltage_factor(self) -> float: ...
    @property
    def reference_index(self) -> int: ...
    @property
    def min_duty(self) -> float: ...
    @property
    def max_duty(self) -> float: ...
    @property
    def thrust_limit(self) -> float: ...
    @property
    def rejected_voltages(self) -> int: ...
    @property
    def voltage_window(self) -> tuple[float, float] | None: ...
    @property
    def last_good_voltage(self) -> float: ...

def duty_to_pwm_report(duty: npt.NDArray[np.float64]) -> npt.NDArray[np.uint16]: ...
def duty_to_can(duty: npt.NDArray[np.float64]) -> npt.NDArray[np.uint16]: ...
def duty_to_dshot(duty: npt.NDArray[np.float64]) -> npt.NDArray[np.uint16]: ...
def gains_to_wire_terms(gains: npt.NDArray[np.float64]) -> npt.NDArray[np.int16]: ...
def gains_from_wire_terms(terms: npt.NDArray[np.int64]) -> npt.NDArray[np.float64]: ...
def clamp_gain(gains: npt.NDArray[np.float64]) -> tuple[npt.NDArray[np.float64], bool]: ...

# --- lqi ---
import numpy as np
from numpy.typing import NDArray

JSK_TO_PAPER: list[int]
MAX_WIRE_GAIN: float
N_VECTORING: int
GRAVITY: float
MAX_TILT_RAD: float

class CareSolveError(RdmError):
    """The Riccati solver failed (not stabilisable, not converged, or invalid input)."""

class LqiSynthesisError(RdmError):
    """LQI synthesis or the LQI control law failed; the message names the argument."""

class PositionControlError(RdmError):
    """Position control rejected its input; the message names the argument."""

def solve_care(
    a: NDArray[np.float64],
    b: NDArray[np.float64],
    q: NDArray[np.float64],
    r: NDArray[np.float64],
    k0: NDArray[np.float64] | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.float64], dict[str, object]]:
    """12-state, 4-input CARE: (P, K = -R^-1 B^T P, report). With k0: Kleinman warm start
    with the cold sign-function method as fallback. report: method ('sign'|'kleinman'),
    iterations, fell_back, relative_residual."""

def augmented_system(
    mass: float, inertia: NDArray[np.float64], allocation: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(A_bar 12x12, B_bar 12x4) of eq. (26) in the JSK state order."""

def gain_set_from_k(k: NDArray[np.float64], clamp: bool = True) -> NDArray[np.float64]:
    """Sec. 4 mapping of K (4x12): (4, 4, 3) array, axes (roll, pitch, yaw, z), (P, I, D)."""

def gyro_compensation(
    allocation: NDArray[np.float64], inertia: NDArray[np.float64]
) -> dict[str, object]:
    """pinv(Q_bar) columns pinv_roll/pinv_pitch/pinv_yaw, inertia, pseudo_inverse, rank."""

def flight_thrust(
    k: NDArray[np.float64],
    state: NDArray[np.float64],
    allocation: NDArray[np.float64],
    inertia: NDArray[np.float64],
    omega: NDArray[np.float64],
) -> tuple[NDArray[np.float64], dict[str, object]]:
    """Eq. (29): (K x_bar + pinv(Q_bar)[0; w x I w], gyro-compensation dict)."""

@_final
class LqiSynthesizer:
    """Warm-started LQI gain synthesizer (weights default to Table V)."""

    def __new__(
        cls,
        q_weights: NDArray[np.float64] | None = None,
        r_weights: NDArray[np.float64] | None = None,
        clamp_gain: bool = True,
        kleinman_tolerance: float | None = None,
        rotors: int | None = None,
    ) -> _Self:
        """``rotors`` (1..MAX_ROTORS) fixed for the synthesizer's life; None: the length of
        ``r_weights``, or 4 without them."""
    @property
    def rotors(self) -> int: ...
    def synthesize(
        self, mass: float, inertia: NDArray[np.float64], allocation: NDArray[np.float64]
    ) -> dict[str, object]:
        """Keys k, p, b, gains, clamp_scales, report. GIL released while solving."""
    def synthesize_wire(
        self, mass: float, inertia: NDArray[np.float64], allocation: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.int16] | None, bytes | None, bool, bool, bool]:
        """The same synthesis as ``synthesize`` as (gains (rotors, 4, 3), rpy/gain int16
        terms (rotors, 7) or None, their RollPitchYawTerms payload or None, every gain
        finite, fell_back, a clamp scale != 1). A result with terms and finite gains is kept
        (``kept_result``). GIL released while solving. While the same problem is asked
        again the same objects are returned again; the arrays are read-only."""
    def kept_result(self) -> dict[str, object] | None:
        """The ``synthesize`` dict of the last result ``synthesize_wire`` kept."""
    def reset(self) -> None: ...
    @property
    def has_solution(self) -> bool: ...
    @property
    def reused(self) -> int:
        """Calls answered with a kept solution: their B-bar bitwise one of the last four
        solved."""

@_final
class PcAxisController:
    """PC-side altitude P-I-D (base thrust) and yaw P-I (angles[2]) of JSK sec. 4."""

    def __new__(cls) -> _Self: ...
    def step(
        self,
        gains: NDArray[np.float64],
        z_error: float,
        z_rate_error: float,
        yaw_error: float,
        feed_forward: NDArray[np.float64],
        dt: float,
    ) -> tuple[NDArray[np.float64], float, int | None]: ...
    @property
    def integrals(self) -> tuple[float, float]: ...

@_final
class PositionController:
    """Eqs. (30)-(36); defaults Table V, integral limit 1 m/s^2 per axis and tilt bound
    ``max_tilt`` = MAX_TILT_RAD (assumptions). ``step`` returns a dict: acceleration, roll,
    pitch, alpha, beta, direction, integral_clamped, saturated (bool) and saturation (the
    names of the outputs cut to the tilt bound: "acceleration", "attitude", "vectoring")."""

    def __new__(
        cls,
        x_pid: tuple[float, float, float] | None = None,
        y_pid: tuple[float, float, float] | None = None,
        integral_limit: tuple[float, float] | None = None,
        k_roll: float | None = None,
        k_pitch: float | None = None,
        k_pitch_vectoring: list[float] | None = None,
        k_roll_vectoring: list[float] | None = None,
        gravity: float | None = None,
        max_tilt: float | None = None,
    ) -> _Self: ...
    def step(
        self,
        position: NDArray[np.float64],
        velocity: NDArray[np.float64],
        target_position: NDArray[np.float64],
        target_velocity: NDArray[np.float64],
        target_yaw: float,
        link_rotations: NDArray[np.float64],
        dt: float,
    ) -> dict[str, object]: ...
    @property
    def integral(self) -> NDArray[np.float64]: ...
    def reset(self) -> None: ...
    def take_integral_action(self, previous: PositionController) -> None:
        """Bumpless gain switch: carry ``previous``'s integral action k_I ∫e per axis."""

def vectoring_angles(n: NDArray[np.float64]) -> tuple[float, float]:
    """Eqs. (33)-(34) for a unit direction n: (alpha, beta)."""

def finite_float_vector(value: object, n: int) -> NDArray[np.float64] | _Literal[False] | None:
    """``value`` if it is a list or tuple of exactly ``n`` exact ``float``s: their float64
    array when all are finite, else False; None for any other value (the caller decides)."""

def servo_target_payload(
    targets: NDArray[np.float64],
    vectoring: tuple[Sequence[float], Sequence[float]] | None,
    pairs: Sequence[tuple[int, int]],
    zero: Sequence[float],
    sign: Sequence[float],
    scale: Sequence[float],
    index: Sequence[int],
) -> tuple[list[float], bytes] | None:
    """The onboard node's servo goals and their ``spinal/ServoControlCmd`` payload: the
    first ``n = min(len(index), len(targets))`` targets with the vectoring joints ``pairs``
    overwritten by ``vectoring``'s (alpha, beta) per unit, and the message with each goal as
    ``round(zero + sign * q / scale)`` ticks saturated to int16. None for anything the Python
    form treats otherwise (other types, a pair outside the goals, a target Python's ``round``
    refuses, an index outside uint8)."""

def spinal_apply_commands(
    items: list[object],
    kinds: bytes,
    first_user_id: int,
    core: SpinalStep,
    master: CanMaster | None,
    now_s: float,
) -> tuple[int, Exception | None]:
    """Spinal's steady command frames in one call: the leading run of ``items`` (the
    rosserial parser's good frames, ``(topic_id, payload, offset)``) whose subscriber kind
    (``kinds[topic_id - first_user_id]``: 1 four_axes/command, 2 rpy/gain, 3 pinv+inertia,
    4 desire_coordinate, 5 servo/target_states, 0 none) it takes, decoded and applied to
    ``core`` (and to ``master``'s servo goals) as the mirror's message handlers do. Returns
    ``(n, error)``: the first ``n`` applied; ``error``, when not None, is what item ``n``'s
    core call raised (that item is done too); otherwise item ``n`` is one it does not take
    (nothing of it applied)."""

def flight_axes(
    position_controller: PositionController,
    pc_axes: PcAxisController,
    gains: NDArray[np.float64],
    state_position: NDArray[np.float64],
    state_velocity: NDArray[np.float64],
    state_yaw: float,
    setpoint_position: NDArray[np.float64],
    setpoint_velocity: NDArray[np.float64],
    setpoint_yaw: float,
    link_rotations: NDArray[np.float64],
    joint_targets: NDArray[np.float64],
    vectoring_joints: list[tuple[int, int]],
    feed_forward: NDArray[np.float64],
    held: bool,
    vectoring: bool,
    min_nz: float,
    dt: float,
) -> (
    tuple[
        float,
        float,
        float,
        tuple[float, ...],
        tuple[float, ...],
        tuple[bool, ...],
        int,
        NDArray[np.float64],
        int | None,
    ]
    | None
):
    """``ControlPipeline.step``'s flight part in one call: the position loop (eqs. 30-36,
    held at zero error when ``held``), per vectoring unit its angles or the joint targets
    (``min_nz``), the PC-side z/yaw axes. Returns (roll, pitch, yaw term, alpha, beta,
    applied, singular units, base thrust, yaw rotor); None, with nothing stepped, for an
    input it does not read (the caller's plain form then runs)."""

# --- bench ---
# Rust-side timing loops of `rdm bench` (crates/rdm_py/src/bench.rs): each times every call
# with std::time::Instant, GIL released, and returns what each step computed.
def time_spinal_steps(
    gains: _np.ndarray,
    pinv: _np.ndarray,
    inertia: tuple[float, float, float, float, float, float],
    now: _np.ndarray,
    gyro: _np.ndarray,
    acc: _np.ndarray,
    mag: _np.ndarray,
    voltage: float,
    command_every: int,
    command_angles: tuple[float, float, float],
    command_base_thrust: _np.ndarray,
    rate_hz: float = 200.0,
    gyro_calib_duration_s: float = 0.0,
) -> dict[str, _Any]:
    """Keys: ns (n,) int64, duty (n, 4), thrust (n, 4), euler (n, 3), invalid."""

def time_lqi_synthesis(
    masses: _np.ndarray, inertias: _np.ndarray, allocations: _np.ndarray, warm: bool = True
) -> dict[str, _Any]:
    """Keys: ns (n,) int64, k (n, 4, 12), failures, fell_back."""

def time_onboard_ticks(
    position: _np.ndarray,
    velocity: _np.ndarray,
    target_position: _np.ndarray,
    target_velocity: _np.ndarray,
    target_yaw: _np.ndarray,
    link_rotations: _np.ndarray,
    dt: float,
    foot_wrench: _np.ndarray,
    foot_allocation: _np.ndarray,
    allocation: _np.ndarray,
    mass: float,
    initial_thrust: _np.ndarray,
    rate_hz: float = 40.0,
    cutoff_hz: float = 1.0,
) -> dict[str, _Any]:
    """Keys: ns (n,) int64, thrust (n, 4), status (n,) uint8, status_names, alpha, beta,
    acceleration (n, 2), failures, position_failures."""

def bench_build_profile() -> str: ...
def time_timer_overhead(n: int = 10000) -> _np.ndarray: ...

# --- planner ---

class QpInputError(RdmError):
    """A QpSolver argument has the wrong shape or holds NaN/-inf (message names it)."""

class PlannerError(RdmError):
    """Bad planner input: description, mode, config key, zeta (message names it)."""

@_final
class QpSolver:
    """Dense QP on Clarabel (rdm_core::qp): min ½xᵀPx + qᵀx s.t. A_eq x = b_eq, G x <= h.
    Fixed sizes; the solver is reused across solves."""

    def __new__(
        cls, n: int, n_eq: int, n_ineq: int, max_iter: int = 50, tolerance: float = 1e-8
    ) -> _Self: ...
    def solve(
        self,
        p: NDArray[np.float64],
        q: NDArray[np.float64],
        a_eq: NDArray[np.float64],
        b_eq: NDArray[np.float64],
        g: NDArray[np.float64],
        h: NDArray[np.float64],
    ) -> tuple[str, NDArray[np.float64]]:
        """(status, x): status one of solved, almost_solved, primal_infeasible,
        dual_infeasible, max_iterations, numerical_error; x is zeros unless solved."""
    @property
    def iterations(self) -> int: ...

@_final
class CorePlanner:
    """Sec. V planner core (rdm_core::planner). ``mode``: "perched" or "flight";
    ``zeta0`` = [p, eta, q]; ``config``: parameter overrides (docs/planner.md)."""

    def __new__(
        cls,
        urdf: str,
        toml: str,
        mode: str,
        zeta0: NDArray[np.float64],
        config: dict[str, object] | None = None,
    ) -> _Self: ...
    @property
    def zeta(self) -> NDArray[np.float64]: ...
    def set_zeta(self, zeta: NDArray[np.float64]) -> None: ...
    @property
    def free(self) -> list[int]: ...
    @property
    def values(self) -> NDArray[np.float64]: ...
    @property
    def layout(self) -> dict[str, object]: ...
    def linearize(self) -> NDArray[np.float64]: ...
    def end_effector_pose(
        self,
    ) -> tuple[tuple[float, float, float], tuple[float, float, float, float]]: ...
    def task_rows(
        self,
        position: list[float],
        orientation: list[float] | None = None,
        axis: list[float] | None = None,
    ) -> tuple[NDArray[np.float64], list[float], list[float]]:
        """End-effector task rows (eqs. 54, 56) at the current state: (rows 6 x n_free,
        step delta-xi [6], weights [6]); rows the target leaves free have weight 0."""
    def step(
        self,
        position: list[float],
        orientation: list[float] | None = None,
        axis: list[float] | None = None,
    ) -> dict[str, object]:
        """At most one of ``orientation`` (quaternion [x, y, z, w]) or ``axis`` (world
        direction of the end-effector x axis, rotation about it free). Keys: status
        ("moved" or "qp_failed:<status>"), position_error, orientation_error (rad; the
        axis angle for an axis target), binding (constraint name or None)."""
    def feasible_force(self) -> tuple[tuple[float, float, float], float] | None: ...

# --- qp ---
# Perching solver choice (PerchQp / PerchController `params`): "solver" is one of
# PERCH_SOLVER_NAMES ("active_set", the default, or "clarabel"); "active_set_max_iter"
# (int, 1..=500) caps the active-set passes before Clarabel takes over. Solution dicts carry
# "fallback" (bool: Clarabel answered an active-set tick); counters() carries "fallback"
# (count of such ticks) next to the per-status counts. "relax_rate_limit" (bool, default
# True): an eq. (49) infeasible only through eq. (48) is solved without it and the thrust
# steps toward that solution (status "rate_limited"; False: "infeasible", thrust held).
# "contact_normal" (3 floats, outward unit normal of the contact surface in foot axes,
# default the ceiling's (0, 0, -1)) and "contact_center" (3 floats, the contact face's centre
# in the foot frame, default (0, 0, 0)) place eqs. (39)-(44) on any plane. solve()/tick()
# take a 4x4 foot_allocation (rows F_n, M_t1, M_t2, M_n; wrench in plane coordinates) or a
# 6x4 one (rows F_x..M_z about the foot origin; wrench in foot axes).
from typing import Literal as _Literal

_PerchSolverName = _Literal["active_set", "clarabel"]

# --- Neuron bank ---
class NeuronBankError(RdmError): ...

@_final
class NeuronBank:
    """Every Neuron of one CAN bus (boards ticked in order, as boards sharing one bus)."""

    def __new__(
        cls,
        boards: list[dict[str, object]],
        tx_capacity: int = ...,  # default 4096 frames
    ) -> _Self: ...
    def tick_wire(self, now: float, stamp: float, wire: CanWire) -> list[int]:
        """:meth:`tick` on a :class:`CanWire`: the frames the master sent; replies go on the
        wire stamped ``stamp`` (the channel clock); the sending board index of each reply."""
    def tick(self, now: float, messages: list[object]) -> list[tuple[int, int, bytes]]: ...
    def attach_bridge(
        self,
        center: int,
        qadr: list[int],
        scale: list[float],
        servos: list[tuple[int, int, int]],
        rotors: list[tuple[int, int]],
        group_boards: list[int],
    ) -> None: ...
    def bridge_push_positions(self) -> None: ...
    def stick_joint(self, joint: int) -> None: ...
    def power_cycle(self, k: int) -> None: ...
    def __len__(self) -> int: ...
    def changes(self) -> list[int]: ...
    def board_changes(self, k: int) -> int: ...
    def count_tx(self, k: int, sent: bool) -> None: ...
    def tx_count(self, k: int) -> tuple[int, int]: ...
    @property
    def bridged(self) -> bool: ...
    def servo_outputs(self, k: int) -> tuple[list[int], list[bool]]: ...
    def esc(self, k: int) -> tuple[int, bool]: ...
    def set_esc_held_value(self, k: int, value: int) -> None: ...
    def set_positions(self, boards: list[int], servos: list[int], ticks: list[float]) -> None: ...
    def set_imu_raw(self, k: int, sensor: int, xyz: list[int]) -> None: ...
    def imu_raw(self, k: int) -> list[list[int]]: ...
    def set_servo_field(self, k: int, index: int, field: str, value: int | None) -> None: ...
    def board_state(self, k: int) -> dict[str, object]: ...

# --- sensor noise ---
from collections.abc import Sequence as _Seq

@_final
class WrenchNoiseCore:
    def __new__(
        cls,
        rated: _Seq[float],
        bias: _Seq[float],
        noise_fraction: float,
        quantize: bool,
        full_scale_counts: float,
    ) -> _Self: ...
    def sample(
        self, ideal: _Seq[float], normals: _Seq[float]
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]: ...
    def sample_at(
        self, sensordata: np.ndarray, force_adr: int, torque_adr: int, normals: _Seq[float]
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`sample` of the 3 + 3 ideal values at the addresses (ValueError outside)."""
    def sample_values_at(
        self, sensordata: np.ndarray, force_adr: int, torque_adr: int, normals: _Seq[float]
    ) -> tuple[float, float, float, float, float, float]:
        """The noisy wrench of :meth:`sample_at` as one tuple of six floats."""

@_final
class RestingSleepCore:
    """The robot's sleep at rest (``rdm_core::sim::resting_sleep``) on MuJoCo's arrays; the
    state of ``rdm.plant.sleep.RestingSleep``, shared with the lockstep kernel."""
    def __new__(
        cls,
        trees: _Seq[int],
        rotors: _Seq[int],
        allowed_value: int,
        never_value: int,
        sleep_bit: int,
        ctrl: _NDArray[_np.float64],
        policy: _NDArray[_np.int32],
        tree_asleep: _NDArray[_np.int32],
        opt: _Any,
    ) -> _Self: ...
    def before_step2(self, step1: Callable[[], object]) -> None: ...
    def wake_next(self) -> None: ...
    def asleep(self) -> bool: ...
    @property
    def trees(self) -> list[int]: ...
    @property
    def rotors(self) -> list[int]: ...
    @property
    def last_ctrl(self) -> _NDArray[_np.float64]: ...
    @property
    def pending(self) -> bool: ...
    @property
    def allowed(self) -> bool: ...
    @property
    def wakes(self) -> int: ...
    @property
    def sleep_on(self) -> bool: ...
    @property
    def settled(self) -> bool: ...

@_final
class NormalStreamCore:
    """Standard normals of one numpy ``Generator``, drawn ``chunk`` at a time
    (``rdm_core::sim::normal_stream``); the sensor noise models' stream."""
    def __new__(cls, rng: _Any, chunk: int = 1024) -> _Self: ...
    def take(self, k: int) -> list[float]: ...
    @property
    def taken(self) -> int: ...
    @property
    def chunk(self) -> int: ...

@_final
class LeptrinoStreamCore:
    """The stream state of one simulated Leptrino sensor (``rdm_core::sim::leptrino_sensor``),
    shared by ``LeptrinoSensorNode`` and the lockstep kernel."""
    def __new__(cls, rated: _Seq[float], temperature: int, sensor_no: int) -> _Self: ...
    @property
    def streaming(self) -> bool: ...
    @streaming.setter
    def streaming(self, value: bool) -> None: ...
    @property
    def temperature(self) -> int: ...
    @temperature.setter
    def temperature(self, value: int) -> None: ...
    @property
    def sensor_no(self) -> int: ...
    @sensor_no.setter
    def sensor_no(self, value: int) -> None: ...
    @property
    def wrench(self) -> list[float]: ...
    @property
    def limits(self) -> list[float]: ...
    def set_wrench(self, values: _Seq[float]) -> None: ...
    def sample_frame(self) -> bytes: ...
    def count_write(self, length: int, written: int, frames: int = 1) -> None: ...
    @property
    def saturated_samples(self) -> int: ...
    @property
    def bad_wrench(self) -> int: ...
    @property
    def frames_sent(self) -> int: ...
    @property
    def bytes_dropped(self) -> int: ...
    @property
    def tx_short(self) -> int: ...

@_final
class ImuNoiseCore:
    def __new__(
        cls,
        gyro_bias: _Seq[float],
        accel_bias: _Seq[float],
        mag_bias: _Seq[float],
        std: _Seq[float],
        range: _Seq[float],
        lsb: _Seq[float] | None,
    ) -> _Self: ...
    def sample(
        self,
        gyro: _Seq[float],
        accel: _Seq[float],
        mag: _Seq[float],
        normals: _Seq[float],
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, bool]: ...
    def sample_at(
        self,
        sensordata: np.ndarray,
        gyro_adr: int,
        accel_adr: int,
        mag_adr: int,
        normals: _Seq[float],
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, bool]:
        """:meth:`sample` of the 3 x 3 ideal values at the addresses (ValueError outside)."""

# --- json_log ---
def json_float_list(values: npt.NDArray[np.float64]) -> str:
    """``"v0,v1,..."``: each value as Python's ``repr(float)``, NaN and infinities as
    ``null`` (the run logger's JSON convention); any stride."""

# --- rotor plant ---
@_final
class RotorPlantCore:
    """ESC state, ceiling models and rotor controls of one plant: the per-physics-step rotor
    work (ESC lag, ceiling distance and ratio, rotor ctrl) in one call (rdm.plant.Plant)."""

    def __new__(
        cls,
        site_ids: list[int],
        actuator_ids: list[int],
        ceiling_height: float | None,
        site_xpos: np.ndarray,
        site_xmat: np.ndarray,
        ctrl: np.ndarray,
    ) -> _Self: ...
    def __len__(self) -> int: ...
    def step(self) -> None:
        """ESC lags advance, then the ceiling-scaled thrusts go into ctrl."""
    def apply(self) -> None:
        """The ceiling-scaled present thrusts into ctrl (no lag step)."""
    def advance_lag(self) -> None: ...
    def thrust(self, i: int) -> float: ...
    def target(self, i: int) -> float: ...
    def set_thrust(self, i: int, value: float) -> None: ...
    def set_target(self, i: int, value: float) -> None: ...
    def set_alpha(self, i: int, value: float) -> None: ...
    def set_ceiling_unity(self, i: int) -> None: ...
    def set_ceiling_parametric(
        self, i: int, radius: float, k1: float, k2_over_radius: float, max_ratio: float
    ) -> None: ...
    def applied(self) -> list[float]: ...
    def set_applied(self, values: list[float]) -> None: ...
    def set_esc_map(
        self, i: int, p2: float, p1: float, p0: float, thrust_max: float, v_factor: float
    ) -> None: ...
    def duty(self, i: int) -> float: ...
    def set_duty(self, i: int, value: float) -> None: ...
    def rejected(self, i: int) -> int: ...
    def set_rejected(self, i: int, value: int) -> None: ...
    def command_duties(self, duties: list[float]) -> None:
        """``Esc.command_duty`` of every rotor in one call (ValueError on a wrong count)."""
    def set_truth_layout(
        self,
        foot_body: int,
        ee_body: int,
        qpos_addresses: list[int],
        dof_addresses: list[int],
        fixed_base: bool,
    ) -> None: ...
    def truth_arrays(
        self,
        xpos: np.ndarray,
        xquat: np.ndarray,
        qpos: np.ndarray,
        qvel: np.ndarray,
        subtree_com: np.ndarray,
    ) -> tuple[np.ndarray, ...]:
        """(base pos, base quat, lin vel, ang vel, joint q, joint qd, CoG, EE pos, thrusts)."""
    def set_truth_record(
        self, new: Callable[[type], Any], cls: type, fields: tuple[str, ...], plate_body: int
    ) -> None:
        """The record ``truth_record`` builds: ``new(cls)`` with its ``__dict__`` filled in
        ``fields`` order (the 18 GroundTruth fields; ValueError otherwise), and the foot plate
        body of the no-contact numbers."""
    def truth_record(
        self,
        time: float,
        xpos: np.ndarray,
        xquat: np.ndarray,
        xmat: np.ndarray,
        qpos: np.ndarray,
        qvel: np.ndarray,
        subtree_com: np.ndarray,
        measured: tuple[int, np.ndarray, np.ndarray, np.ndarray, np.ndarray, float] | None = None,
    ) -> Any:
        """The whole ground-truth record: the ``truth_arrays`` values, the EE quaternion as
        zeros (filled by the caller) and ``measured`` = ``FootContactTracker.measure``'s
        (points, force, torque, zmp, slip, slip_yaw), or None for no plate contact and no
        anchor: no contact, force/torque ``-(R.T @ 0)`` (R the plate frame), ZMP NaN, slip 0,
        yaw 0. ValueError on a ``measured`` of another length."""

# --- plate contact (ground truth) ---
@_final
class ContactGateCore:
    """The plant's collision gate (``rdm.plant.contact_gate``): proves from MjData's views that
    the next position pass can produce no contact and keeps ``mjDSBL_CONTACT`` of the model's
    ``opt.disableflags`` in step (set: contacts off for that pass)."""

    def __new__(
        cls,
        dt: float,
        slack: float,
        planes: list[tuple[list[float], list[float]]],
        boxes: list[tuple[list[float], list[float], list[float]]],
        geoms: list[tuple[int, float, list[float | None]]],
        free_dof: int,
        hinges: list[tuple[int, int]],
        slides: list[int],
        root_body: int,
        opt: Any,
        bit: int,
        geom_xpos: np.ndarray,
        xpos: np.ndarray,
        xanchor: np.ndarray,
        qvel: np.ndarray,
    ) -> _Self:
        """``planes`` (point, normal) and ``boxes`` (centre, row-major rotation, half sizes)
        are the static obstacles; ``geoms`` (geom, rbound, margin per obstacle or None); the
        robot's free joint's first dof, its hinges (joint, dof) and slide dofs; its root body;
        the model's ``MjOption`` and ``mjDSBL_CONTACT``; the MjData views. ValueError on a
        bad ``dt`` / ``slack`` or margins that do not match the obstacles."""
    def read(self) -> tuple[float, float]:
        """``(clearance, reach)`` [m] of the present views; contact is impossible in the next
        pass when clearance > reach (NaN: possible)."""
    def update(self) -> bool:
        """Decide for the next pass (after ``mj_step2``); True when contacts are now off.
        ValueError (contacts turned on) when the views are too short."""
    def enable(self) -> None:
        """Contacts on now (the state may change outside the steps)."""
    @property
    def off(self) -> bool:
        """True while contacts are off."""
    @property
    def off_steps(self) -> int:
        """Steps after which contacts were off."""
    @property
    def on_steps(self) -> int:
        """Steps after which contacts were on."""

@_final
class PlateContactCore:
    """The foot plate's contact measurement of ``FootContactTracker.measure_contacts``
    (rdm.plant.truth): contact sums, foot-frame force, torque and ZMP from MuJoCo's contact
    views and ``efc_force`` (elliptic or pyramidal cones, ``mj_contactForce``'s forces)."""

    def __new__(cls, geom_body: list[int], environment: list[bool], plate_body: int) -> _Self:
        """``geom_body`` = ``model.geom_bodyid``; ``environment[g]``: geom g is an
        environment surface; ``plate_body``: the foot plate. ValueError on unequal lengths."""
    def measure(
        self,
        geom: np.ndarray,
        frame: np.ndarray,
        pos: np.ndarray,
        efc_address: np.ndarray,
        dim: np.ndarray,
        friction: np.ndarray,
        efc_force: np.ndarray,
        origin: np.ndarray,
        rot: np.ndarray,
        pyramidal: bool,
    ) -> tuple[int, np.ndarray, np.ndarray, np.ndarray]:
        """``(points, force, torque, zmp)`` (what the robot applies, foot frame; ZMP NaN
        without normal force; NaN sums stay NaN) of the plate's contacts. ValueError on
        mismatched shapes, IndexError on a geom or constraint row out of range."""
    @staticmethod
    def yaw_about(r0: np.ndarray, r1: np.ndarray) -> float | None:
        """The turn from ``r0`` to ``r1`` (row-major, 9 values) about ``r0``'s z axis; None
        when a value on the way is NaN."""

@_final
class FootTrackerCore:
    """The foot plate's first-contact anchor and last contact time (``release_time``: the
    longest contact gap the anchor survives) with the cached view of MuJoCo's contact geom
    pairs; the state of ``FootContactTracker`` (rdm.plant.truth), shared with the lockstep
    kernel's plant step."""

    def __new__(cls, plate_geoms: list[int], release_time: float) -> _Self:
        """ValueError on a negative or NaN ``release_time``."""
    release_time: float
    @property
    def last_contact_time(self) -> float: ...
    @property
    def anchor_pos(self) -> np.ndarray | None:
        """The plate's world position at first contact (a new array), or None."""
    @property
    def anchor_rot(self) -> np.ndarray | None:
        """The plate's 3x3 rotation at first contact (a new array), or None."""
    def idle(self) -> bool:
        """No anchor and no contact time to release."""
    def reset(self) -> None: ...
    def track(self, time: float, in_contact: bool) -> bool:
        """One step with or without a plate contact; True: a contact without an anchor."""
    def set_anchor(self, pos: np.ndarray, rot: np.ndarray) -> None:
        """The anchor: position (3) and row-major rotation (9)."""
    def update(self, data: Any, ncon: int, time: float) -> int:
        """One step's bookkeeping: 0 done, 1 no cached view of this contact list (nothing
        changed), 2 a plate contact began without an anchor (the time is stamped)."""
    def keep_view(self, data: Any, ncon: int, address: int, geom: np.ndarray) -> None: ...
    def view_of(self, data: Any, ncon: int) -> np.ndarray | None: ...
    @property
    def view_address(self) -> int | None: ...
    def forget_view(self) -> None:
        """Drop the cached view (counted in ``view_misses``)."""
    @property
    def view_misses(self) -> int: ...
    def plate_in(self, geom: np.ndarray) -> bool: ...

@_final
class PlantStateCore:
    """The plant's lazy-forward flags (``stale``, ``needs_step1``), its state ``version``,
    the rejected servo goals and whether a step can run in Rust (``rotors_in_core`` and no
    ``wrenches_held``); shared by ``rdm.plant.Plant`` and the lockstep kernel."""

    def __new__(cls) -> _Self: ...
    stale: bool
    needs_step1: bool
    rotors_in_core: bool
    wrenches_held: bool
    @property
    def version(self) -> int: ...
    @property
    def rejected_commands(self) -> int: ...
    def synced(self) -> None: ...
    def touched(self) -> None: ...
    def reset(self) -> None: ...
    def begin_step(self) -> bool:
        """Whether this step runs ``mj_step1``."""
    def stepped(self) -> None: ...
    def reject(self, n: int) -> None: ...

@_final
class PlantStepCore:
    """``rdm.plant.Plant``'s physics step and lazy forward pass (``Plant.step``,
    ``Plant.sync``), shared with the lockstep kernel; the face's ``callbacks`` (rotors outside
    the core, apply and re-aim held wrenches, the tracker face's ``update``) run only when
    the state needs them."""

    def __new__(
        cls,
        model: Any,
        data: Any,
        mj: Sequence[Any],
        flags: tuple[int | None, int | None, int],
        opt: Any,
        sensor_bit: int,
        state: PlantStateCore,
        rotors: RotorPlantCore,
        gate: ContactGateCore | None,
        tracker: FootTrackerCore,
        sleep: RestingSleepCore | None,
        callbacks: Sequence[Callable[..., None]],
    ) -> _Self: ...
    def step(self, n: int) -> None:
        """Advance ``n`` physics steps."""
    def sync(self) -> None:
        """The forward pass on the present state (held wrenches re-aimed first)."""

# --- CAN master and wire ---
class CanMasterError(RdmError): ...

@_final
class CanMaster:
    """Spinal's CAN master (``rdm_core::firmware::can_master``); its Python face is
    ``rdm.nodes.can_master.CanMaster``."""

    def __new__(cls, boot_delay_ms: int = 5000, start_ms: int = 0) -> _Self: ...
    def tick_ms(
        self, now_ms: int, messages: list[object]
    ) -> tuple[int, int, list[tuple[int, bytes]]]:
        """(state_index, pending_events, frames to send) after receiving ``messages``."""
    def tick_wire(self, now_ms: int, stamp: float, wire: CanWire) -> tuple[int, int, int, int]:
        """(state_index, pending_events, frames_sent, log_len) on a wire."""
    def tick_wire_steady(self, now_ms: int, stamp: float, wire: CanWire, drain_at: int) -> int:
        """``tick_wire``; frames sent if running, no event pending and log_len < drain_at,
        else -1 (the tuple is then in ``last_wire_tick``)."""
    @property
    def tx_count(self) -> int:
        """Frames sent: every ``tick_wire`` frame plus those ``count_sent`` added."""
    def count_sent(self, n: int) -> None:
        """Add ``n`` frames the python-can path sent."""
    @property
    def pending_events(self) -> int:
        """Log events not yet taken by ``pop_events``."""
    @property
    def last_wire_tick(self) -> tuple[int, int, int, int]: ...
    @property
    def state_index(self) -> int: ...
    @property
    def motor_number(self) -> int: ...
    @property
    def uav_model(self) -> int | None: ...
    @property
    def rx_count(self) -> int: ...
    @property
    def connected(self) -> bool: ...
    @property
    def events_dropped(self) -> int: ...
    @property
    def goal_resyncs(self) -> int: ...
    def rx_errors(self) -> list[tuple[str, int]]: ...
    def rx_kinds(self) -> list[tuple[str, int]]: ...
    def set_motor_duties(self, duties: list[float]) -> None: ...
    def try_set_motor_duties(self, duties: list[float]) -> bool:
        """Apply and return True only for exactly ``motor_number`` valid Python floats."""
    def servo_reports(self) -> list[tuple[bool, int, int, int, int, bool]]:
        """(send_data_flag, angle, temperature, current, error, torque_enable) per servo."""
    def servo_keys(self) -> list[tuple[int, int]]:
        """(slave, position) per servo, table order."""
    def set_servo_target_list(self, targets: list[tuple[int, int, int]]) -> None:
        """``set_servo_target`` for each (slave, index, value)."""
    def set_servo_target(self, slave: int, index: int, value: int) -> None: ...
    def set_servo_torque(self, slave: int, index: int, enable: bool) -> None: ...
    def set_servo_current(self, slave: int, index: int, value: int) -> None: ...
    def configure_board(
        self, can_id: int, payload: bytes, reboot_slave: int | None = None
    ) -> None: ...
    def neurons(self) -> list[tuple[int, int, bool, bool, int, bool, int]]: ...
    def servo(self, k: int, i: int) -> tuple: ...
    def imu(
        self,
    ) -> list[tuple[int, list[tuple[int, int, int] | None], int]]: ...
    def pop_events(self) -> list[tuple[int, str, int]]: ...

@_final
class CanWire:
    """The Neuron bus between a ``CanMaster`` and a ``NeuronBank`` without python-can."""

    def __new__(
        cls,
        queue_capacity: int = ...,  # default 4096 frames per direction
        log_capacity: int = ...,  # default 65536 logged frames
        logging: bool = True,
    ) -> _Self: ...
    @property
    def frames(self) -> int: ...
    @property
    def dropped(self) -> tuple[int, int]: ...
    @property
    def log_len(self) -> int: ...
    def drain_log(self, channel: str) -> str: ...
    def set_loss(self, p: float, seed: int) -> None: ...
    def bus_off(self, start: float, disturbed_s: float) -> None: ...
    def fault_counters(self) -> dict[str, float]: ...

# NeuronBank.tick_wire(now, stamp, wire) -> list[int] (board index of each reply) is stubbed
# in NeuronBank above (crates/rdm_py/src/neuron_bank.rs).

# --- JSON record ---
def json_record(values: object) -> str | None:
    """A flat dict record (plain str keys; None, bool, float, int, str, 1-D float64 arrays,
    lists of floats) as compact ``json.dumps`` text, NaN/inf as ``null``; None otherwise."""

# --- MCAP chunks ---
@_final
class McapChunkBatch:
    """Message records of one MCAP chunk in the making (rdm.sim.mcap_writer.McapWriter):
    each add appends one Message record (log time = publish time) and its index entry; the
    add methods return 0 when they decline (nothing added), 1 when added, 2 when added and
    the chunk buffer is now over ``chunk_size`` bytes."""

    def __new__(cls, chunk_size: int) -> _Self: ...
    def set_base(self, base: int) -> None:
        """The chunk buffer's size the next record follows (call with the batch empty)."""
    def next_offset(self) -> int:
        """Chunk buffer offset the next record starts at."""
    def __len__(self) -> int: ...
    def add(self, channel: int, sequence: int, time: int, data: bytes) -> int:
        """One message with ``data`` (bytes) as its payload."""
    def add_record(self, channel: int, sequence: int, time: int, values: object) -> int:
        """One message whose payload is the flat dict record as ``json_record`` writes it."""
    def add_fields(
        self, channel: int, sequence: int, time: int, attributes: object, keys: object
    ) -> int:
        """One message whose payload is ``{k: attributes[k] for k in keys}`` (a dict and a
        tuple of keys) as ``json_record`` writes it; a missing key declines."""
    def take(
        self,
    ) -> tuple[bytes, int, int, int, list[tuple[int, list[tuple[int, int]]]]] | None:
        """(records, count, first time, last time, [(channel, [(time, offset), ...])]) of the
        pending messages (channels in first-message order), emptying the batch; None when
        empty."""

# --- capture index, Leptrino scan ---
def capture_index_records(
    start: int,
    n: int,
    staged: tuple[int, Sequence[tuple[float, int]]] | None,
    clock: Callable[[], float],
    last: int,
) -> tuple[bytes, int]:
    """``(records, last)`` of a capture write of ``n`` bytes at offset ``start``: 16-byte
    ``<qQ`` records (time ns, end offset) for the bytes the staged marks ``(base, [(time s,
    end)])`` cover at their times and one for the rest at ``clock()`` (called only when bytes
    are left); times never go below ``last``. Raises ValueError / OverflowError for a time
    that is NaN or outside int64 nanoseconds (``rdm.sim.capture_index.TimedCaptureFile``)."""
    ...

def leptrino_ok_sample_run(data: bytes) -> tuple[int, int, int, bytes | None]:
    """(end, count, last_start, last_payload) of the leading run of whole OK-sample frames."""

# --- rosserial frames ---
class RosserialFrameError(RdmError):
    """A rosserial frame that cannot be built or scanned (topic id, payload type or length,
    max_payload out of range); the message names the argument and the rule."""

def rosserial_scan(
    buf: bytearray, pos: int, base: int, max_payload: int, rescan: bool
) -> tuple[list[tuple[Any, ...]], int, int, bool, bool, bool]:
    """Scan a rosserial receive buffer from ``pos`` (``base``: stream offset of ``buf[0]``).

    Returns ``(events, pos, frames, clean, broke, reset)``: good frames as
    ``(topic_id, payload, offset)``, other events as ``(kind, offset, data)`` with kind
    ``"skip"`` or the reject reason; used by ``rdm.protocol.rosserial.framing.FrameParser``.
    Raises :class:`RosserialFrameError` for a ``max_payload`` that is not an ``int >= 0``."""

def rosserial_frame(topic_id: int, payload: bytes | bytearray | memoryview) -> bytes:
    """The rosserial v2 frame of ``payload`` on ``topic_id`` (``framing.encode_frame``).
    Raises :class:`RosserialFrameError` naming the rule for a topic id that is not an int in
    0..65535, a payload of another type, or one longer than the uint16 length field."""

# --- Spinal frames ---
def spinal_imu_frame(
    topic_id: int,
    now_ms: int,
    synced: bool,
    sync_tick: int,
    sync_ns: int,
    acc: tuple[float, float, float] | list[float],
    output: SpinalStepOutput,
    mag: tuple[float, float, float] | list[float],
) -> bytes | None:
    """The Spinal mirror's whole ``spinal/Imu`` frame at MCU tick ``now_ms``: the stamp of a
    ``ClientClock`` in state (``synced``, ``sync_tick``, ``sync_ns``), ``acc`` and ``mag``,
    the output's filtered angular velocity and quaternion, as float32; the bytes of
    ``encode_frame(topic_id, imu_codec.encode(msg))``. None when an argument is not of these
    exact types, a value is not finite or overflows float32, or the stamp does not fit."""

def spinal_duty_list(output: SpinalStepOutput, n: int, idle: float) -> list[float] | None:
    """``[min(1.0, max(idle, d)) for d in output.duty.tolist()[:n]]``, or None when the step
    has events or ``n`` is not in 1..(the step's ESC outputs) (the mirror's Python path then
    decides)."""

def spinal_servo_states_frame(
    topic_id: int, sec: int, nsec: int, master: CanMaster
) -> bytes | bool | None:
    """The whole ``spinal/ServoStates`` frame of the servos with send_data_flag in the
    master's table (index = position in the table) with stamp ``(sec, nsec)``: the bytes of
    ``encode_frame(topic_id, codec.encode(ServoBridge.states(...)))``. None when no servo
    has send_data_flag; False when an argument is not an exact int in range, ``master`` is
    not a ``CanMaster`` or a reporting servo's index passes 255 (the Python path decides)."""

# --- ground truth ---
# WrenchNoiseCore.sample_values_at and RotorPlantCore.{set_truth_layout, truth_arrays} are
# stubbed in their classes above (crates/rdm_py/src/{sensor_sim,rotor_plant}.rs).

# --- lockstep kernel ---
@_final
class SampleSchedule:
    """The plant bridge's sampling schedule (``PlantBridge.schedule``; the lockstep kernel
    advances the same object): tick ``n`` (from 0) takes a reading when ``n % every == 0``;
    ``every`` 0 is off. Each argument >= 0 (ValueError naming it otherwise)."""

    def __new__(
        cls, imu_every: int, wrench_every: int, mocap_every: int, truth_every: int
    ) -> _Self: ...
    def advance(self) -> tuple[bool, bool, bool, bool]:
        """Take the next tick: (imu, wrench, mocap, truth) due at it."""
    def peek(self) -> tuple[bool, bool, bool, bool]:
        """(imu, wrench, mocap, truth) due at the next tick, without taking it."""
    @property
    def every(self) -> tuple[int, int, int, int]:
        """Ticks between the samples of (imu, wrench, mocap, truth); 0: off."""
    @property
    def count(self) -> int:
        """Ticks taken so far."""

@_final
class StopFlag:
    """The lockstep loop's stop request (``Lockstep.stop`` sets it, the Rust loop reads it)."""

    def __new__(cls) -> _Self: ...
    def set(self) -> None:
        """Ask the loop to stop after the tick in progress."""
    def clear(self) -> None:
        """Withdraw the request."""
    def is_set(self) -> bool:
        """Whether a stop was asked."""

@_final
class SpinalMirrorState:
    """The Spinal mirror's clock, IMU sample and battery state, shared by its Python tick and
    the lockstep kernel: ``SpinalMirrorState(battery_input, gyro, acc, mag)`` before the
    first tick."""

    def __new__(
        cls,
        battery_input: float,
        gyro: Sequence[float],
        acc: Sequence[float],
        mag: Sequence[float],
    ) -> _Self: ...
    def set_imu_sample(
        self, gyro: Sequence[float], acc: Sequence[float], mag: Sequence[float]
    ) -> None:
        """The IMU sample the next control steps and ``imu`` publications use: gyro rad/s,
        acc m/s^2, mag uT (three numbers each)."""
    @property
    def gyro(self) -> tuple[float, float, float]: ...
    @property
    def acc(self) -> tuple[float, float, float]: ...
    @property
    def mag(self) -> tuple[float, float, float]: ...
    def tick_begin(self, now: float) -> int:
        """The tick's ms at ``now`` (s; never before the last tick's); ``now_s`` the latest
        time. ValueError for a non-finite ``now``."""
    def control_due(self) -> bool:
        """Whether a control step is due at ``now_s``."""
    def battery_sample(self, now_ms: int) -> bool:
        """The battery task at ``now_ms``; False: the sample is not finite (rejected)."""
    def step_voltage(self) -> float:
        """``battery_voltage``, else ``battery_input``."""
    @property
    def now_ms(self) -> int | None: ...
    @property
    def now_s(self) -> float: ...
    @property
    def can_ms(self) -> int | None: ...
    @can_ms.setter
    def can_ms(self, value: int | None) -> None: ...
    @property
    def next_control(self) -> float | None: ...
    @next_control.setter
    def next_control(self, value: float | None) -> None: ...
    @property
    def battery_due_ms(self) -> int: ...
    @property
    def battery_input(self) -> float: ...
    @battery_input.setter
    def battery_input(self, value: float) -> None: ...
    @property
    def adc_scale(self) -> float: ...
    @adc_scale.setter
    def adc_scale(self, value: float) -> None: ...
    @property
    def battery_voltage(self) -> float | None: ...
    @property
    def next_pub_ms(self) -> int: ...
    @next_pub_ms.setter
    def next_pub_ms(self, value: int) -> None: ...

@_final
class TickCounter:
    """The lockstep loop's next base tick (the Rust loop sets it after every tick)."""

    def __new__(cls) -> _Self: ...
    def get(self) -> int:
        """The next base tick."""

@_final
class PlantBridgeCore:
    """The plant bridge's state (targets and duties last commanded, battery voltage applied,
    time-mismatch count), its sampling schedule and the Neuron banks it couples: the one
    object ``rdm.nodes.plant_bridge.PlantBridge`` and the lockstep kernel tick. ``period``
    must be finite and > 0 (ValueError otherwise)."""

    def __new__(
        cls,
        targets: list[float],
        rotors: int,
        period: float,
        schedule: SampleSchedule,
        banks: list[NeuronBank],
    ) -> _Self: ...
    def couple(self, plant_time: float, now: float, qpos: np.ndarray) -> tuple[bool, bool]:
        """Count a time mismatch, then each bank's coupling into ``targets``/``duties``;
        returns ``(targets_changed, duties_changed)``."""
    @property
    def targets(self) -> np.ndarray:
        """Servo targets (rad) last written (a copy)."""
    @property
    def duties(self) -> np.ndarray:
        """Rotor duties last written (a copy)."""
    @property
    def schedule(self) -> SampleSchedule:
        """The sampling schedule."""
    @property
    def time_mismatches(self) -> int:
        """Ticks that found the plant more than half a period away."""
    def set_fixed_battery(self, volts: float | None) -> None:
        """The battery is the constant ``volts`` or (None) a function of time from now on."""
    def apply_voltage(self, volts: float) -> bool:
        """Take ``volts`` as this tick's voltage; True if it differs from the last applied."""
    @property
    def voltage(self) -> float | None:
        """The last voltage applied (None before the first tick)."""
    @property
    def battery_steady(self) -> bool:
        """True when the battery is a constant already applied."""

@_final
class LockstepKernel:
    """The lockstep loop behind ``rdm.nodes.lockstep.Lockstep``: per base tick the due nodes
    in order, the barriers, one physics step, then pacing and progress; fast paths for the
    firmware side's steady milliseconds (``rdm.nodes.lockstep_kernel``, docs/sim.md)."""

    def __new__(
        cls,
        dt: float,
        names: Sequence[str],
        periods: Sequence[float],
        offsets: Sequence[int],
        ticks: Sequence[Any],
        physics: Any | None,
        clock: Any,
        stop: StopFlag,
        counter: TickCounter,
        barriers: Sequence[Callable[[], Any]] = ...,
        speed: float | None = None,
        progress: Callable[[float, float, int, float], Any] | None = None,
        progress_every: float = 1.0,
        profile: bool = False,
        wall_clock: Callable[[], float] | None = None,
        sleep: Callable[[float], Any] | None = None,
    ) -> _Self: ...
    def attach_plant(
        self,
        stepper: PlantStepCore,
        state: PlantStateCore,
        rotors: RotorPlantCore,
        qpos: _F,
        sensordata: _F,
        ctrl: _F,
        servo_act: Sequence[int],
    ) -> None:
        """The plant's parts (typed, read by ``rdm.nodes.lockstep_kernel``)."""
    def attach_bridge(
        self,
        index: int,
        core: PlantBridgeCore,
        plan: Callable[[], tuple[Any, ...] | None],
    ) -> None: ...
    def attach_bank(self, index: int, bank: NeuronBank, wire: CanWire) -> None: ...
    def attach_spinal(
        self,
        index: int,
        node: Any,
        state: SpinalMirrorState,
        master: CanMaster,
        wire: CanWire,
        drain_at: int,
    ) -> None: ...
    def attach_leptrino(
        self,
        index: int,
        stream: LeptrinoStreamCore,
        idle: Callable[[], bool],
        write: Callable[[bytes, list[tuple[float, int]]], int],
    ) -> None: ...
    def set_touches(self, index: int, parts: list[str]) -> None:
        """The parts (``plant``, ``bridge``, ``bank``, ``spinal``, ``leptrino``) node
        ``index``'s Python tick may change; default all."""
    def run(self, n: int, ticks: list[Any], own: list[bool], paced: bool = True) -> int:
        """Advance ``n`` base ticks with the nodes' present ``tick``s (``own``: the class's
        own method, so its fast path may run); ``paced``: with pacing and progress; the
        next ``k``."""
    @property
    def k(self) -> int: ...
    profile: bool
    """Time every node tick, the barriers and the physics step (``stats()``: ``fast_ns``,
    ``python_ns``, ``barriers_ns``, ``physics_ns``)."""
    def stats(self) -> dict[str, Any]:
        """Ticks per node on the fast path and in Python, physics steps, boundaries, contact
        tracker updates, the Spinal busy ms run in the kernel (``spinal_busy``: ``steps``,
        ``battery_samples``, ``imu_frames``, ``servo_frames``, and the hand-overs to the
        mirror's Python continuations ``finish_step`` / ``finish_publish``, and the ms the
        mirror received in Python with the rest run in the kernel / in Python:
        ``receive_then_kernel`` / ``receive_then_python``), ``base_ticks``, ``wall_time``
        (paced runs) and, measured with ``profile``, the wall ns of each."""
