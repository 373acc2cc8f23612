"""Type stubs of the compiled core :mod:`rdm._rdm` (see crates/rdm_py)."""

__version__: str

class RdmError(ValueError):
    """Base class of every error raised by rdm's core."""

# --- lqi ---
import numpy as np  # noqa: E402
from numpy.typing import NDArray  # noqa: E402

LQI_STATE_NAMES: list[str]
JSK_TO_PAPER: list[int]
MAX_WIRE_GAIN: float
N_VECTORING: int
GRAVITY: float

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

class LqiSynthesizer:
    """Warm-started LQI gain synthesizer (weights default to Table V)."""

    def __init__(
        self,
        q_weights: NDArray[np.float64] | None = None,
        r_weights: NDArray[np.float64] | None = None,
        clamp_gain: bool = True,
        kleinman_tolerance: float | None = None,
    ) -> None: ...
    def synthesize(
        self, mass: float, inertia: NDArray[np.float64], allocation: NDArray[np.float64]
    ) -> dict[str, object]:
        """Keys k, p, b, gains, clamp_scales, report. GIL released while solving."""
    def reset(self) -> None: ...
    @property
    def has_solution(self) -> bool: ...

class PcAxisController:
    """PC-side altitude P-I-D (base thrust) and yaw P-I (angles[2]) of JSK sec. 4."""

    def __init__(self) -> None: ...
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

class PositionController:
    """Eqs. (30)-(36); defaults Table V, integral limit 1 m/s^2 per axis (assumption)."""

    def __init__(
        self,
        x_pid: tuple[float, float, float] | None = None,
        y_pid: tuple[float, float, float] | None = None,
        integral_limit: tuple[float, float] | None = None,
        k_roll: float | None = None,
        k_pitch: float | None = None,
        k_pitch_vectoring: list[float] | None = None,
        k_roll_vectoring: list[float] | None = None,
        gravity: float | None = None,
    ) -> None: ...
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

def vectoring_angles(n: NDArray[np.float64]) -> tuple[float, float]:
    """Eqs. (33)-(34) for a unit direction n: (alpha, beta)."""
