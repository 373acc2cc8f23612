"""The onboard node's controller signals as one flat record: ``/onboard/signals`` of
``rdm sim``'s ``signals.mcap`` and of the live telemetry (``rdm sim --live``,
``rdm onboard --live``)."""

from __future__ import annotations

from typing import Any

import numpy as np

_FLOAT64 = np.dtype(np.float64)


def _floats_of(v: Any) -> list | None:
    """A 1-D float64 array's values as Python floats (``tolist``), else a flat list of
    floats (None for None)."""
    if type(v) is np.ndarray and v.dtype is _FLOAT64 and v.ndim == 1:
        return v.tolist()
    if v is None:
        return None
    return [float(x) for x in np.asarray(v, dtype=float).reshape(-1)]


def onboard_signals(o: Any, now: float) -> dict[str, Any]:
    """What the onboard node ``o`` (:class:`rdm.nodes.onboard.OnboardNode`) saw and
    commanded at its last tick, for plots beside the ground truth: Spinal's attitude and gyro
    as received over the UART, the mocap sample and the setpoint it used, its attitude
    targets, flight thrusts and vectoring angles, the joint angles Spinal reported and the
    goals sent back, the foot sensor's wrench. A flat record of floats and float lists (None
    where there is no value yet), read without copies beyond ``tolist``."""
    c = o.last_command
    euler = o.imu_euler
    mocap = o.mocap
    sp = o.setpoint
    foot = o.foot.wrench if o.foot is not None else None
    goals = o.last_servo_goals
    return {
        "t": now,
        "imu_euler": list(euler) if euler is not None else None,
        "imu_gyro": _floats_of(o.imu_gyro),
        "mocap_position": _floats_of(mocap[0]) if mocap is not None else None,
        "mocap_velocity": _floats_of(mocap[1]) if mocap is not None else None,
        "mocap_yaw": (float(mocap[2]) if mocap is not None and mocap[2] is not None else None),
        "setpoint_position": _floats_of(sp.position),
        "setpoint_velocity": _floats_of(sp.velocity),
        "setpoint_yaw": float(sp.yaw),
        "target_angles": list(c.angles) if c is not None else None,
        "flight_thrust": _floats_of(c.flight_thrust) if c is not None else None,
        "vectoring_alpha": list(c.alpha) if c is not None else None,
        "vectoring_beta": list(c.beta) if c is not None else None,
        "present_q": _floats_of(o.present_q),
        "servo_goals": list(goals) if goals is not None else None,
        "foot_wrench": _floats_of(foot),
    }
