"""Inputs of the benchmark cases, built from the default robot (``Robot.default()``).

* A periodic joint trajectory of ``CYCLE`` configurations (one per 40 Hz tick, 10 s): the
  middle link pitches and yaws (q2, q3, q4), so the mass properties, the rotor allocation
  Q̄(q) and the foot allocation change every tick while Q̄ stays invertible (rho > 1e-3,
  cond < 150 over the cycle). Longer runs repeat the cycle; the wrap-around is smooth, so
  a warm start always comes from a neighbouring configuration.
* A 200 Hz IMU stream (gentle attitude oscillation, noise) and an armed Spinal setup with
  Hydrus-like gains.
* A perching scenario: the robot hangs from the ceiling by its foot, rotors 1-2 press the
  foot (Table VII), the measured foot wrench oscillates slowly around 10 N of contact
  force with small tangential forces and moments (well inside friction and ZMP limits,
  so every tick is feasible); the position controller runs beside it on a small circle.

Everything is deterministic (fixed seeds), so the Rust and the Python paths time the very
same inputs.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

#: Configurations in one period of the joint trajectory (10 s at 40 Hz).
CYCLE = 400
SPINAL_RATE_HZ = 200.0
TICK_RATE_HZ = 40.0


def trajectory_q(n_q: int, count: int = CYCLE) -> np.ndarray:
    """(count, n_q) joint configurations of one period of the benchmark trajectory."""
    phase = 2.0 * np.pi * np.arange(count) / count
    q = np.zeros((count, n_q))
    q[:, 1] = 0.25 * np.sin(phase)
    q[:, 2] = 0.3 * np.sin(phase + 1.0)
    q[:, 3] = -0.25 * np.sin(phase)
    return q


@dataclass(frozen=True)
class RobotCycle:
    """Model quantities along one period of the trajectory."""

    mass: float
    inertia: np.ndarray  # (CYCLE, 3, 3), about the CoG, CoG frame
    allocation: np.ndarray  # (CYCLE, 4, 4) Q̄: rows f_z, m_x, m_y, m_z (CoG frame)
    foot_allocation: np.ndarray  # (CYCLE, 4, 4): rows F_z, M_x, M_y, M_z at the foot
    link_rotations: np.ndarray  # (CYCLE, 2, 3, 3): C <- L_i of the vectoring units


@lru_cache(maxsize=1)
def robot_cycle() -> RobotCycle:
    """Evaluate the default robot along the trajectory (cached: ~CYCLE model calls)."""
    from rdm.model import Robot

    robot = Robot.default()
    qs = trajectory_q(robot.n_q)
    inertia, allocation, foot_allocation, rotations = [], [], [], []
    mass = 0.0
    for q in qs:
        o = robot.evaluate(q)
        mass = float(o["mass"])
        inertia.append(o["inertia"])
        allocation.append(o["allocation_bar"])
        full = np.asarray(o["allocation"])  # rows f_x f_y f_z m_x m_y m_z about the CoG
        foot = np.asarray(o["foot_in_cog"])[:3, 3]  # foot origin in the CoG frame
        # Moment about the foot origin: M_foot = M_cog - p_foot x F (axes shared).
        m_foot = full[3:6] - np.cross(foot, full[0:3].T).T
        foot_allocation.append(np.vstack([full[2], m_foot]))
        rotations.append(np.stack(o["unit_parent_rotations"]))
    return RobotCycle(
        mass=mass,
        inertia=np.array(inertia),
        allocation=np.array(allocation),
        foot_allocation=np.array(foot_allocation),
        link_rotations=np.array(rotations),
    )


def cycled(a: np.ndarray, n: int) -> np.ndarray:
    """First ``n`` entries of ``a`` repeated along axis 0 (contiguous)."""
    reps = -(-n // len(a))
    return np.ascontiguousarray(np.concatenate([a] * reps)[:n])


# --- 200 Hz Spinal step -------------------------------------------------------------------


@dataclass(frozen=True)
class SpinalInputs:
    """Setup and input stream of the armed Spinal step."""

    gains: np.ndarray  # (4, 4, 3)
    pinv: np.ndarray  # (4, 3)
    inertia: tuple[float, float, float, float, float, float]
    now: np.ndarray  # (n,)
    gyro: np.ndarray  # (n, 3)
    acc: np.ndarray  # (n, 3)
    mag: np.ndarray  # (n, 3)
    voltage: float
    command_every: int
    command_angles: tuple[float, float, float]
    command_base_thrust: np.ndarray  # (4,)


def spinal_inputs(n: int, seed: int = 7) -> SpinalInputs:
    """Armed-flight inputs for ``n`` Spinal steps at 200 Hz (a command every 5 steps: 40 Hz)."""
    rng = np.random.default_rng(seed)
    gains = np.zeros((4, 4, 3))
    gains[:, 0, :] = gains[:, 1, :] = [3.0, 0.5, 0.8]
    gains[:, 2, 2] = 0.4
    t = np.arange(1, n + 1) / SPINAL_RATE_HZ
    s = np.sin(2.0 * np.pi * 0.5 * t)
    gyro = np.column_stack([0.1 * s, -0.05 * np.cos(t), 0.02 * np.ones(n)])
    gyro += 0.005 * rng.standard_normal((n, 3))
    acc = np.column_stack([0.3 * s, -0.2 * np.ones(n), 9.8 * np.ones(n)])
    acc += 0.05 * rng.standard_normal((n, 3))
    mag = np.array([30.0, 2.0, -40.0]) + 0.3 * rng.standard_normal((n, 3))
    return SpinalInputs(
        gains=gains,
        pinv=np.tile([0.5, 0.5, 0.2], (4, 1)),
        inertia=(0.1, 0.1, 0.2, 0.0, 0.0, 0.0),
        now=t,
        gyro=np.ascontiguousarray(gyro),
        acc=np.ascontiguousarray(acc),
        mag=np.ascontiguousarray(mag),
        voltage=24.5,
        command_every=5,
        command_angles=(0.01, 0.0, 0.05),
        command_base_thrust=np.full(4, 6.0),
    )


def python_spinal(inputs: SpinalInputs):
    """The ordinary binding configured exactly as the Rust timing loop configures its core."""
    from rdm.control.attitude import SpinalStep

    s = SpinalStep(SPINAL_RATE_HZ, gyro_calib_duration_s=0.0)
    s.set_uav_info(4, 16)
    s.set_pwm_info_hydrus_example()
    s.set_gains(inputs.gains)
    s.set_pinv_inertia(inputs.pinv, inputs.inertia)
    s.flight_config(0, 0.0)
    s.flight_config(160, 0.0)
    return s


# --- LQI synthesis ------------------------------------------------------------------------


@dataclass(frozen=True)
class LqiInputs:
    """``n`` configurations along the trajectory (one per 40 Hz tick)."""

    masses: np.ndarray  # (n,)
    inertias: np.ndarray  # (n, 3, 3)
    allocations: np.ndarray  # (n, 4, 4)


def lqi_inputs(n: int) -> LqiInputs:
    """Mass, inertia and Q̄ for ``n`` consecutive ticks of the trajectory."""
    cycle = robot_cycle()
    return LqiInputs(
        masses=np.full(n, cycle.mass),
        inertias=cycled(cycle.inertia, n),
        allocations=cycled(cycle.allocation, n),
    )


# --- 40 Hz onboard tick -------------------------------------------------------------------


@dataclass(frozen=True)
class TickInputs:
    """Inputs of ``n`` onboard ticks: position step + perching controller tick."""

    position: np.ndarray  # (n, 2)
    velocity: np.ndarray  # (n, 2)
    target_position: np.ndarray  # (n, 2)
    target_velocity: np.ndarray  # (n, 2)
    target_yaw: np.ndarray  # (n,)
    link_rotations: np.ndarray  # (n, 2, 3, 3)
    dt: float
    foot_wrench: np.ndarray  # (n, 6) raw sensor wrench
    foot_allocation: np.ndarray  # (n, 4, 4)
    allocation: np.ndarray  # (n, 4, 4)
    mass: float
    initial_thrust: np.ndarray  # (4,)


def tick_inputs(n: int, seed: int = 11) -> TickInputs:
    """A perched robot for ``n`` ticks at 40 Hz (see the module docstring)."""
    rng = np.random.default_rng(seed)
    cycle = robot_cycle()
    t = np.arange(n) / TICK_RATE_HZ
    w = 2.0 * np.pi * 0.1 * t
    circle = np.column_stack([0.05 * np.cos(w), 0.05 * np.sin(w)])
    circle_velocity = np.column_stack([-0.05 * np.sin(w), 0.05 * np.cos(w)]) * 2.0 * np.pi * 0.1
    wrench = np.column_stack(
        [
            0.5 * np.sin(0.7 * t),
            0.4 * np.cos(0.5 * t),
            6.0 + 1.0 * np.sin(0.3 * t),
            0.05 * np.sin(0.9 * t),
            0.2 + 0.05 * np.cos(0.4 * t),
            0.1 * np.sin(0.2 * t),
        ]
    )
    wrench += rng.standard_normal((n, 6)) * [0.05, 0.05, 0.2, 0.005, 0.005, 0.01]
    return TickInputs(
        position=np.ascontiguousarray(circle + 0.002 * rng.standard_normal((n, 2))),
        velocity=np.ascontiguousarray(circle_velocity + 0.01 * rng.standard_normal((n, 2))),
        target_position=np.zeros((n, 2)),
        target_velocity=np.zeros((n, 2)),
        target_yaw=0.1 * np.sin(0.05 * t),
        link_rotations=cycled(cycle.link_rotations, n),
        dt=1.0 / TICK_RATE_HZ,
        foot_wrench=np.ascontiguousarray(wrench),
        foot_allocation=cycled(cycle.foot_allocation, n),
        allocation=cycled(cycle.allocation, n),
        mass=cycle.mass,
        initial_thrust=np.array([5.0, 5.0, 0.0, 0.0]),
    )
