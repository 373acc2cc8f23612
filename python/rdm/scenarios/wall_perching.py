"""``wall-perching``: perch on a vertical wall with horizontal thrust and friction (the paper's
first item of future work, its conclusion), with the perching QP of eqs. (37)-(49) on the
wall's plane (``contact_normal``, docs/perch.md "Contact plane").

Posture: the flat posture (q1..q6 = 0, the take-off and Fig. 9 start posture): the root link
along the foot's +x, the foot box's -x side face the contact face, the foot rotors (the
perch rotors of Table VII, at the root link's tip) at the height of that face. Tilting the
foot unit's pitch joint beta1 to ``WALL_BETA1`` turns their thrust ``WALL_TILT`` from vertical
toward -x: the wall-push posture. The horizontal thrust then acts 2 cm from the line of the
wall's reaction, so pressing puts almost no pitch moment on the robot (in the hanging posture
of ``perching-hanging`` the foot rotors are 0.42 m below the foot: a 15 N press there needs
~6 N m of pitch moment, beyond the rotors' differential; docs/scenarios.md).

Phases (simulated time):

1. boot, arm at ``ARM_AT``, climb to ``CLIMB_Z``;
2. approach: the x setpoint moves toward the wall (at -x of the foot) at ``APPROACH_SPEED``
   until the foot sensor's normal force on the wall (-F_x, what the onboard PC sees) exceeds
   ``CONTACT_N``; the setpoint then stays ``PRESS_DX`` inside the wall;
3. tilt to the wall-push posture over ``TILT_S``;
4. perched: the perching control on (eq. 20, the QP on the wall plane) for ``HOLD_S``; the
   wall's friction takes ``WEIGHT_SHARE`` of the weight off the rotors
   (``ControlPipeline.set_perch_weight_share``: the hover feed-forward sheds that share and
   cancels the moment friction puts about the CoG), ramped in over ``SHARE_RAMP_S`` after
   the switch and back out before perching off;
5. leave: perching off (λ_perch rate-limited to zero), beta1 back to level, the x setpoint
   ``LEAVE_DX`` away from the wall, hover.

Vectoring (eqs. 33-36) is off (``OnboardConfig.vectoring``): the units follow the joint
targets, which is how the script sets beta1 (with it on, the controller would level the foot
unit); x and y are flown by pitch and roll (``POSITION_GAINS``). ASSUMPTION.

The wall: a vertical plate (MuJoCo box, ASSUMPTION: 0.30 m tall, 0.60 m wide, from 0.20 m
below to 0.10 m above the foot's contact face) whose face is ``WALL_X`` from the foot's start
position. The foot box's side face (0.15 m wide, 0.06 m tall; docs/model.md) is the contact
face: outward normal (+1, 0, 0) in foot axes, centre (-0.05, 0, -0.03). Contact parameters:
the ceiling's (Table VII mu = 0.9, mu_z = 0.5).

Metrics (ground truth from MuJoCo over the perched window, from ``SETTLE_S`` after the perch
switch to its end): contact kept, slip, min normal force, ZMP margin on the side face (in the
plane's coordinates, computed here from the contact wrench), friction-cone usage, the share of
the weight friction carries (-F_z / m g, over the full share: up to ``SHARE_RAMP_S`` before
perching off), the total rotor thrust saved against the ``FLIGHT_REF_S`` of flight before the
switch, the largest rotor thrust, tilt, the QP's solved ticks; after leaving: the foot off the
wall and the CoG height error.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from rdm.plant.mjcf import CONTACT_SURFACE_PREFIX, ContactParams, add_env_geom
from rdm.sim import Metric
from rdm.sim.plots import plot_panels

from .common import (
    ScenarioResult,
    SetpointRamp,
    finish,
    observed,
    roll_pitch,
    run_stack,
    truth_arrays,
)
from .perching import POSITION_GAINS, onboard_config, truth_cog
from .stack import Stack, build_stack

ARM_AT = 1.5  # s
CLIMB_Z = 0.8  # m: CoG height of the hover (flat posture)
CLIMB_SPEED = 0.3  # m/s
WAIT_S = 1.5  # s after the climb before the approach
APPROACH_SPEED = 0.05  # m/s
APPROACH_MAX = 0.4  # m: the approach gives up (no contact) after this much travel
CONTACT_N = 3.0  # N: normal force on the wall that counts as contact
PRESS_DX = 0.02  # m: the x setpoint this far inside the wall after contact
#: Tilt of the foot rotors' thrust from vertical toward -x in the wall-push posture, and its
#: beta1 (level is -q1 = 0). ASSUMPTION (ours, docs/scenarios.md).
WALL_TILT = np.radians(30.0)
WALL_BETA1 = -float(WALL_TILT)
TILT_S = 3.0  # s for beta1 level <-> WALL_BETA1
HOLD_S = 6.0  # s perched (with the weight share handed over and back)
#: Share of the weight the wall's friction carries while perched: the hover feed-forward is
#: scaled by 1 - share (``ControlPipeline.set_perch_weight_share``), ramped over
#: ``SHARE_RAMP_S`` after the perch switch and back before perching off. ASSUMPTION (ours,
#: docs/scenarios.md: within the friction cone with mu = 0.9 and the 20 N rotor limit).
WEIGHT_SHARE = 0.10
SHARE_RAMP_S = 1.0
#: The friction-share metric's floor: 2/3 of ``WEIGHT_SHARE`` (the held altitude integral and
#: the model's thrust-to-force error take some back; measured 0.093 of 0.10).
SHARE_MIN = WEIGHT_SHARE * 2.0 / 3.0
#: s of flight before the perch switch that the thrust saving is measured against
FLIGHT_REF_S = 0.5
SETTLE_S = 1.0  # s after the perch switch before the metrics' window
RELEASE_S = 1.0  # s after perching off before beta1 goes back
LEAVE_DX = 0.3  # m
LEAVE_SPEED = 0.1  # m/s
DEFAULT_DURATION = 28.0
#: Wall plate (ASSUMPTION, module docstring): its face's x relative to the foot's start
#: position, extent below/above the foot's contact face in the hover, half width, half
#: thickness.
WALL_X = -0.15
WALL_BELOW, WALL_ABOVE, WALL_HALF_Y, WALL_HALF_T = 0.20, 0.10, 0.30, 0.01
WALL_GEOM = f"{CONTACT_SURFACE_PREFIX}_wall"
#: Foot origin above the CoG in the flat posture (docs/model.md: CoG at (0.4832, 0, -0.0454)
#: in the foot frame at q = 0).
FOOT_ABOVE_COG = 0.0454
#: The foot box's -x side face in foot axes (docs/model.md: box 0.10 x 0.15 x 0.06, its top
#: the ceiling contact face).
FACE_NORMAL = (1.0, 0.0, 0.0)
FACE_CENTER = (-0.05, 0.0, -0.03)
FACE_HALF = (0.03, 0.075)  # m: along t1 (up) and t2 (y)
MU = (0.9, 0.9, 0.5)
#: Perching QP on the side face: the plane, its half sizes with the margin Table VII keeps on
#: the top face (0.04/0.07 of 0.05/0.075), ε_z = 2 N. ASSUMPTION.
PERCH_PARAMS: dict = {
    "epsilon_z": 2.0,
    "contact_normal": list(FACE_NORMAL),
    "contact_center": list(FACE_CENTER),
    "half_size_x": 0.025,
    "half_size_y": 0.07,
}


def wall_face_x(base_position: tuple[float, float, float]) -> float:
    """World x of the wall's face (``WALL_X`` from the foot's start position)."""
    return base_position[0] + WALL_X


def wall_scene(base_position: tuple[float, float, float]) -> Callable[[mujoco.MjSpec], None]:
    """The ``StackOptions.scene`` callable adding the wall plate to the world."""
    contact = ContactParams()
    face = wall_face_x(base_position)
    foot_z = CLIMB_Z + FOOT_ABOVE_COG
    y = base_position[1]

    def edit(spec: mujoco.MjSpec) -> None:
        add_env_geom(
            spec,
            contact,
            name=WALL_GEOM,
            type=mujoco.mjtGeom.mjGEOM_BOX,
            size=[WALL_HALF_T, WALL_HALF_Y, (WALL_BELOW + WALL_ABOVE) / 2],
            pos=[face - WALL_HALF_T, y, foot_z + (WALL_ABOVE - WALL_BELOW) / 2],
            rgba=[0.85, 0.85, 0.8, 0.7],
        )

    return edit


def posture_points(t0: float, beta_from: float, beta_to: float, duration: float, n_q: int):
    """Cosine joint-space segment of beta1 only, every other joint at 0 (the flat posture)."""
    points = []
    for k in range(11):
        s = 0.5 - 0.5 * np.cos(np.pi * k / 10)
        q = np.zeros(n_q)
        q[7] = beta_from + s * (beta_to - beta_from)
        points.append((t0 + duration * k / 10, q))
    return points


class WallPerchingScript:
    """The phase machine (module docstring), run by the stack's script node every 10 ms."""

    def __init__(self) -> None:
        self.phase = "boot"
        self.ramp: SetpointRamp | None = None
        self.t_end = 0.0
        self.t_contact: float | None = None
        self.t_perch: float | None = None
        self.t_release: float | None = None
        self.t_leave: float | None = None
        self.x_contact: float | None = None
        self._last = 0.0
        self._fold_end = 0.0
        #: world x of the wall's face (set by :func:`run`)
        self.face_x = float("nan")

    def _normal_force(self, ob: Any, now: float) -> float | None:
        """The foot sensor's force on the wall (-F_x: the wall is at the foot's -x)."""
        if ob.foot is None:
            return None
        w = ob.foot.latest(now, ob.config.foot_timeout_s)
        return None if w is None else -float(w[0])

    def __call__(self, stack: Stack, now: float) -> None:
        dt = now - self._last
        self._last = now
        ob = stack.onboard
        n_q = ob.robot.n_q
        if self.phase == "boot":
            if now >= ARM_AT:
                self.ramp = SetpointRamp.arm_and_climb(ob, truth_cog(stack), CLIMB_SPEED, CLIMB_Z)
                self.phase = "climb"
            return
        assert self.ramp is not None
        self.ramp.step(dt)
        if self.phase == "climb" and self.ramp.arrived:
            self.t_end = now + WAIT_S
            self.phase = "wait"
        elif self.phase == "wait" and now >= self.t_end:
            goal = self.ramp.position.copy()
            goal[0] -= APPROACH_MAX
            self.ramp.set_goal(goal, APPROACH_SPEED)
            self.phase = "approach"
        elif self.phase == "approach":
            fn = self._normal_force(ob, now)
            if fn is not None and fn > CONTACT_N:
                self.t_contact = now
                cog = truth_cog(stack)
                self.x_contact = float(cog[0])
                hold = self.ramp.position.copy()
                hold[0] = cog[0] - PRESS_DX
                self.ramp.position = hold
                self.ramp.set_goal(hold.copy())
                ob.set_trajectory(posture_points(now, 0.0, WALL_BETA1, TILT_S, n_q))
                self.t_end = now + TILT_S
                self.phase = "tilt"
            elif self.ramp.arrived:
                self.phase = "no contact"
        elif self.phase == "tilt" and now >= self.t_end:
            ob.request_perch(True)
            self.t_perch = now
            self.t_end = now + HOLD_S
            self.phase = "perched"
        elif self.phase == "perched":
            into = min((now - (self.t_perch or now)) / SHARE_RAMP_S, 1.0)
            left = min((self.t_end - now) / SHARE_RAMP_S, 1.0)
            ob.control.set_perch_weight_share(WEIGHT_SHARE * max(min(into, left), 0.0))
            if now >= self.t_end:
                self.phase = "unloaded"
        if self.phase == "unloaded":
            ob.control.set_perch_weight_share(0.0)
            ob.request_perch(False)
            self.t_release = now
            self.t_end = now + RELEASE_S
            self.phase = "release"
        elif self.phase == "release" and now >= self.t_end:
            ob.set_trajectory(posture_points(now, WALL_BETA1, 0.0, TILT_S, n_q))
            self.t_end = now + TILT_S
            self.phase = "untilt"
        elif self.phase == "untilt" and now >= self.t_end:
            goal = self.ramp.position.copy()
            goal[0] += LEAVE_DX + PRESS_DX
            self.ramp.set_goal(goal, LEAVE_SPEED)
            self.t_leave = now
            self.phase = "leave"
        elif self.phase == "leave" and self.ramp.arrived:
            self.phase = "hover"
        ob.set_target(self.ramp.position, 0.0, self.ramp.velocity)


def run(
    base: str | Path,
    duration: float = DEFAULT_DURATION,
    seed: int = 0,
    uart: str = "inproc",
    speed: float | None = None,
    log: bool = True,
    observer: Callable[[Stack, float], None] | None = None,
    **stack_overrides: Any,
) -> ScenarioResult:
    """Run the scenario (module docstring); ``observer(stack, now)`` as in ``perching.run``."""
    from .common import sim_stack_options

    if "onboard" not in stack_overrides:
        stack_overrides["onboard"] = onboard_config(
            perch_params=dict(PERCH_PARAMS), position_gains=dict(POSITION_GAINS), vectoring=False
        )
    opts = sim_stack_options(seed, uart, speed=speed, log=log, **stack_overrides)
    if opts.scene is None:
        from dataclasses import replace

        opts = replace(opts, scene=wall_scene(tuple(opts.base_position)))
    script = WallPerchingScript()
    script.face_x = wall_face_x(tuple(opts.base_position))
    stack = build_stack("wall-perching", base, opts, observed(script, observer))
    wall = run_stack(stack, duration)
    return finish(evaluate(stack, script), duration, wall)


def plane_quantities(force: np.ndarray, torque: np.ndarray) -> dict[str, np.ndarray]:
    """The contact wrench the foot applies (foot axes, about the foot origin; rows = samples)
    in the side face's plane: F_n (along -x), F_t1 (up), F_t2 (y), ZMP (t1, t2) about the face
    centre, eqs. (43)-(44) with p_ZMP_z = 0."""
    c = np.array(FACE_CENTER)
    m_c = torque - np.cross(c, force)
    # plane axes for the normal (+1, 0, 0): t1 = +z, t2 = +y, d = -x (docs/perch.md)
    fn, ft1, ft2 = -force[:, 0], force[:, 2], force[:, 1]
    mt1, mt2 = m_c[:, 2], m_c[:, 1]
    with np.errstate(invalid="ignore", divide="ignore"):
        zmp = np.stack([-mt2 / fn, mt1 / fn], axis=1)
    return {"fn": fn, "ft1": ft1, "ft2": ft2, "zmp": zmp}


def evaluate(stack: Stack, script: WallPerchingScript) -> ScenarioResult:
    """The metrics of the module docstring from MuJoCo's ground truth and the status records."""
    a = truth_arrays(stack)
    t = a["t"]
    nan = float("nan")
    mass = float(stack.plant.model.body_subtreemass[1])
    weight = mass * 9.80665
    pq = plane_quantities(a["force"], a["torque"])
    window = np.zeros_like(t, bool)
    if script.t_perch is not None:
        end = script.t_release if script.t_release is not None else t[-1]
        window = (t >= script.t_perch + SETTLE_S) & (t <= end)
    rp = roll_pitch(a["quat"])
    # the full share: from SETTLE_S after the switch to the start of the ramp back
    full = window & (t <= (script.t_release or 0.0) - SHARE_RAMP_S)
    # flight before the switch: the wall-push posture pressed by the flight thrust alone
    before = np.zeros_like(t, bool)
    if script.t_perch is not None:
        before = (t >= script.t_perch - FLIGHT_REF_S) & (t < script.t_perch)
    if window.any() and full.any() and before.any():
        fn = pq["fn"][window]
        kept = float(np.mean(a["contact"][window]))
        # the truth's slip is world (x, y) (the ceiling's plane): on the wall the foot would
        # slide down, so the foot origin's 3-D displacement over the window is the slip here
        foot = a["foot"][window]
        slip_mm = float(np.max(np.linalg.norm(foot - foot[0], axis=1)) * 1e3)
        zmp = pq["zmp"][window]
        with np.errstate(invalid="ignore"):
            margin = np.minimum(FACE_HALF[0] - np.abs(zmp[:, 0]), FACE_HALF[1] - np.abs(zmp[:, 1]))
            cone = np.hypot(pq["ft1"][window], pq["ft2"][window]) / (MU[0] * fn)
        margin_mm = float(np.nanmin(margin) * 1e3) if np.isfinite(margin).any() else nan
        cone_max = float(np.nanmax(cone)) if np.isfinite(cone).any() else nan
        share = -pq["ft1"][full] / weight
        share_mean, share_min = float(np.mean(share)), float(np.min(share))
        fn_min, fn_mean = float(np.min(fn)), float(np.mean(fn))
        thrust_max = float(np.max(a["thrust"][window]))
        flight_total = float(np.mean(np.sum(a["thrust"][before], axis=1)))
        saved = flight_total - float(np.mean(np.sum(a["thrust"][full], axis=1)))
        tilt = float(np.degrees(np.max(np.abs(rp[window]))))
    else:
        kept = slip_mm = margin_mm = cone_max = share_mean = share_min = nan
        fn_min = fn_mean = thrust_max = tilt = flight_total = saved = nan
    statuses: dict[str, int] = {}  # from SETTLE_S after the switch
    transition: dict[str, int] = {}  # the first SETTLE_S
    for rec in stack.status:
        s = rec.get("perch_status")
        if script.t_perch is None or s is None:
            continue
        counts = statuses if rec.get("t", 0.0) >= script.t_perch + SETTLE_S else transition
        counts[s] = counts.get(s, 0) + 1
    solved = statuses.get("solved", 0) + statuses.get("almost_solved", 0)
    total = sum(statuses.values())
    off_wall = height_err = nan
    if script.t_leave is not None and t[-1] > script.t_leave:
        off_wall = float(a["foot"][-1, 0] + FACE_CENTER[0] - script.face_x)
        height_err = float(abs(a["cog"][-1, 2] - CLIMB_Z))
    metrics = [
        Metric("wall contact reached", float(script.t_contact is not None), 1.0, "", "near"),
        Metric("perched on the wall", float(script.t_perch is not None), 1.0, "", "near"),
        Metric("foot contact kept while perched", kept, 1.0, "fraction", "min", limit=1.0),
        Metric("foot slip while perched (3-D)", slip_mm, None, "mm", "max", limit=1.0),
        Metric("min normal force on the wall", fn_min, None, "N", "min", limit=1.0),
        Metric("mean normal force on the wall", fn_mean, None, "N", "info"),
        Metric("min ZMP margin to the side face's edge", margin_mm, None, "mm", "min", limit=0.0),
        Metric("max friction-cone usage |F_t|/(mu F_n)", cone_max, None, "", "max", limit=1.0),
        Metric(
            "weight share carried by friction (mean, full share)",
            share_mean,
            None,
            "fraction",
            "min",
            limit=SHARE_MIN,
        ),
        Metric("weight share carried by friction (min, full share)", share_min, None, "", "info"),
        Metric("total rotor thrust saved vs the flight before", saved, None, "N", "info"),
        Metric("max rotor thrust while perched", thrust_max, None, "N", "info"),
        Metric("max |roll|,|pitch| while perched", tilt, None, "deg", "max", limit=10.0),
        Metric(
            "perching QP solved ticks",
            solved / total if total else nan,
            None,
            "fraction",
            "min",
            limit=0.99,
        ),
        Metric("foot face off the wall after leaving", off_wall, None, "m", "min", limit=0.15),
        Metric("CoG height error at the end", height_err, None, "m", "max", limit=0.1),
    ]
    facts = {
        "t_contact": script.t_contact,
        "t_perch": script.t_perch,
        "t_release": script.t_release,
        "final_phase": script.phase,
        "perch_status_counts": statuses,
        "perch_status_counts_first_s": transition,
        "mass_kg": mass,
        "weight_share_commanded": WEIGHT_SHARE,
        "total_thrust_flight_n": flight_total,
    }
    _plots(stack, a, pq, rp)
    return ScenarioResult("wall-perching", stack, metrics, facts)


def _plots(stack: Stack, a: dict, pq: dict, rp: np.ndarray) -> None:
    t = a["t"]
    plot_panels(
        stack.folder.plot("wall-perching"),
        t,
        [
            ("CoG position", {"x": a["cog"][:, 0], "y": a["cog"][:, 1], "z": a["cog"][:, 2]}, "m"),
            ("rotor thrust", {f"rotor{i + 1}": a["thrust"][:, i] for i in range(4)}, "N"),
            (
                "wall force (plane)",
                {"F_n": pq["fn"], "F_t1 (up)": pq["ft1"], "F_t2": pq["ft2"]},
                "N",
            ),
            ("ZMP on the side face", {"t1": pq["zmp"][:, 0], "t2": pq["zmp"][:, 1]}, "m"),
            ("beta1", {"beta1": a["q"][:, 7]}, "rad"),
            ("attitude", {"roll": np.degrees(rp[:, 0]), "pitch": np.degrees(rp[:, 1])}, "deg"),
        ],
        title="wall-perching: approach, wall-push posture, perched, leave",
    )
