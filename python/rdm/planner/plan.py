"""``plan``: iterate the planner step (eqs. 50-51) to a target."""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from rdm import _rdm
from rdm.planner.core import PlannerSetup, make_core
from rdm.planner.trajectory import Trajectory, Unreachable

#: Position tolerance for "reached" [m] and orientation tolerance [rad].
TOLERANCE = 1e-3
ORIENTATION_TOLERANCE = 1e-3
#: Steps without 10 µm of improvement before a plan is declared stalled.
PATIENCE = 40
MAX_STEPS = 800
#: m per rad of orientation error in the progress measure of an oriented target (a stall is
#: PATIENCE steps without 10 µm of position error + ANGLE_LENGTH x angle error).
#: ASSUMPTION: 0.1 m, the tools' length (1 mrad = 0.1 mm at the tool point).
ANGLE_LENGTH = 0.1


def _record(core: _rdm.CorePlanner, lay: dict, target: np.ndarray) -> tuple:
    v = core.values
    pos, _ = core.end_effector_pose()
    s, n = lay["collision"]
    a, m = lay["airflow"]
    return (
        core.zeta.copy(),
        v[lay["thrust"][0] : lay["thrust"][0] + lay["thrust"][1]].copy(),
        v[lay["torque"][0] : lay["torque"][0] + lay["torque"][1]].copy(),
        float(v[lay["rho"][0]]),
        float(v[s : s + n].min()) if n else np.inf,
        float(v[a : a + m].min()) if m else np.inf,
        np.array(pos),
        float(np.linalg.norm(np.array(pos) - target)),
    )


def run_core(
    core: _rdm.CorePlanner,
    target: Sequence[float],
    mode: str,
    max_steps: int = MAX_STEPS,
    tolerance: float = TOLERANCE,
    axis: Sequence[float] | None = None,
) -> Trajectory:
    """Step ``core`` toward ``target`` = (x, y, z[, roll, pitch, yaw]) until the error is
    below ``tolerance`` (and the orientation error below ``ORIENTATION_TOLERANCE``) or
    progress stalls. ``axis``: with a 3-D target, the world direction the end-effector x axis
    (the tool axis) must reach, the rotation about it free (the 5-D task of docs/planner.md
    "Target kinds"; the core's ``s2_ee_orientation`` weighs it)."""
    target = tuple(float(t) for t in target)
    pos = np.array(target[:3])
    quat = None
    if axis is not None:
        axis = [float(a) for a in axis]
        if len(target) != 3 or len(axis) != 3 or not np.linalg.norm(axis) > 0:
            raise ValueError("axis: 3 non-zero values, with a 3-D target only")
    if len(target) == 6:
        # imported here: scipy.spatial costs 0.3 s of start-up, and most targets are points
        from scipy.spatial.transform import Rotation

        quat = list(Rotation.from_euler("xyz", target[3:]).as_quat())
    elif len(target) != 3:
        raise ValueError(f"target: expected 3 or 6 values, got {len(target)}")
    lay = core.layout
    rows = [_record(core, lay, pos)]
    bindings: list[str | None] = [None]
    best, since, blocking, reached = rows[0][-1], 0, None, False
    rot_err = 0.0
    for _ in range(max_steps):
        r = core.step(list(pos), quat, axis)
        rot_err = float(r["orientation_error"])
        rot_ok = rot_err < ORIENTATION_TOLERANCE if quat or axis else True
        if r["position_error"] < tolerance and rot_ok:
            reached = True
            break
        if r["status"] != "moved":
            blocking = f"qp_failed ({r['binding'] or 'no dual'})"
            break
        rows.append(_record(core, lay, pos))
        bindings.append(r["binding"])
        err = rows[-1][-1] + (rot_err * ANGLE_LENGTH if quat or axis else 0.0)
        if err < best - 1e-5:
            best, since = err, 0
        else:
            since += 1
            if since >= PATIENCE:
                seen = Counter(b for b in bindings[-PATIENCE:] if b)
                blocking = seen.most_common(1)[0][0] if seen else "none (local minimum)"
                break
    if not reached and blocking is None:
        # the last reported orientation error (before the last step)
        final_rot_ok = rot_err < ORIENTATION_TOLERANCE if quat or axis else True
        if rows[-1][-1] < tolerance and final_rot_ok:
            reached = True
        else:
            blocking = "max_steps"
    cols = list(zip(*rows, strict=True))
    kw = dict(
        zeta=np.array(cols[0]), thrusts=np.array(cols[1]), torques=np.array(cols[2]),
        rho=np.array(cols[3]), clearance=np.array(cols[4]), airflow=np.array(cols[5]),
        ee_position=np.array(cols[6]), error=np.array(cols[7]), target=target, mode=mode,
        binding=bindings,
    )  # fmt: skip
    if reached:
        return Trajectory(**kw, reached=True)
    return Unreachable(**kw, blocking=blocking)


def plan(
    robot: str | Path | tuple[str, str] | PlannerSetup,
    target: Sequence[float],
    start_zeta: Sequence[float] | None = None,
    mode: str = "perched",
    **config: float,
) -> Trajectory:
    """Plan from ``start_zeta`` (default: the mode's default start) to ``target``.

    ``robot``: a shipped name, a TOML path, (urdf, toml) texts, or a ``PlannerSetup``.
    ``config``: planner parameters (docs/planner.md), e.g. ``kappa_position=0.005``.
    Returns a ``Trajectory`` (reached) or an ``Unreachable`` naming the blocking constraint.
    """
    setup = robot if isinstance(robot, PlannerSetup) else PlannerSetup.for_robot(robot, mode)
    if config:
        setup = PlannerSetup(setup.urdf, setup.toml, setup.mode, {**setup.config, **config})
    if len(target) == 6 and "s2_ee_orientation" not in setup.config:
        setup = PlannerSetup(
            setup.urdf, setup.toml, setup.mode, {**setup.config, "s2_ee_orientation": 0.1}
        )
    core = make_core(setup, None if start_zeta is None else np.asarray(start_zeta, float))
    return run_core(core, target, setup.mode)
