# ruff: noqa: RUF002  (paper notation: Greek letters, minus and times signs)
"""The 40 Hz control pipeline of the onboard node, without any I/O (paper Sec. IV, Fig. 6).

Per tick, at the PRESENT joint angles q (from ``servo/states``):

1. model: m, I(q), Q̄(q) (rows f_z, m_x, m_y, m_z, CoG frame), Q̄_foot(q) (same rows about the
   foot origin), the vectoring units' parent rotations, the hover thrust;
2. LQI synthesis (eqs. 21-27, warm-started) every ``lqi_every`` ticks -> per-rotor gains (the
   last good ones are kept when it fails);
3. position control (eqs. 30-36) -> φ_d, θ_d and the vectoring angles α_i, β_i;
4. PC-side axes (JSK sec. 4): base thrust = z P/I/D + feed-forward, yaw P/I -> ``angles[2]``;
5. perching (eqs. 37-49, Sec. VII-B filter) -> λ_perch added to the base thrust (eq. 20).

Every failure is counted in :attr:`ControlPipeline.counts`; outputs are always finite.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass

import numpy as np

from rdm import _rdm
from rdm.control.lqi import LqiSynthesizer, PcAxisController, gyro_compensation
from rdm.control.perch import PERCH_ROTORS, PerchController, PerchResult
from rdm.control.position import PositionController
from rdm.nodes.onboard_config import OnboardConfig

INT16_MIN, INT16_MAX = -32768, 32767
#: How many recent q's model terms :meth:`ControlPipeline.update_model` keeps.
MODEL_CACHE_SIZE = 4
#: Largest share of the weight :meth:`ControlPipeline.set_perch_weight_share` hands to the
#: contact: the rest stays on the hover feed-forward. ASSUMPTION (a bound, not a tuning).
PERCH_WEIGHT_SHARE_MAX = 0.5

try:  # the ufunc np.clip ends in for float arrays, without its Python dispatch layers
    from numpy._core.umath import clip as _clip
except ImportError:  # numpy < 2
    _clip = np.clip


try:  # the gufunc np.linalg.lstsq ends in, and the error handler it installs around it
    from numpy.linalg import _umath_linalg
    from numpy.linalg._linalg import _raise_linalgerror_lstsq
except ImportError:  # another numpy layout: np.linalg.lstsq throughout
    _umath_linalg = None
_EPS = np.finfo(np.float64).eps


def _lstsq_solution(a: np.ndarray, rhs: list[float]) -> np.ndarray:
    """``np.linalg.lstsq(a, rhs, rcond=None)[0]`` for a float64 (m, n) ``a`` and m Python
    floats: the same gufunc call (same LAPACK driver, rcond ``eps * max(m, n)``, error state
    and LinAlgError), without the wrapper's type dispatch and residual/singular-value work.
    Anything else goes through ``np.linalg.lstsq``."""
    if (
        _umath_linalg is None
        or a.__class__ is not np.ndarray
        or a.dtype != np.float64
        or a.ndim != 2
        or a.shape[0] != len(rhs)
        or 0 in a.shape
        or not all(v.__class__ is float for v in rhs)
    ):
        return np.linalg.lstsq(a, rhs, rcond=None)[0]
    m, n = a.shape
    b = np.array(rhs)[:, None]
    handler = _raise_linalgerror_lstsq
    with np.errstate(call=handler, invalid="call", over="ignore", divide="ignore", under="ignore"):
        x = _umath_linalg.lstsq(a, b, _EPS * max(n, m), signature="ddd->ddid")[0]
    return x.squeeze(axis=-1)


def _all_finite(a: np.ndarray) -> bool:
    """``bool(np.all(np.isfinite(a)))``; a float64 array's elements checked as the Python
    floats ``tolist`` gives (the same values; numpy's reduction costs more on small arrays,
    e.g. the 48 LQI gains)."""
    if type(a) is np.ndarray and a.dtype == np.float64 and a.size <= 64:
        return all(map(math.isfinite, a.ravel().tolist()))
    return bool(np.logical_and.reduce(np.isfinite(a), axis=None))


def to_wire(value: float) -> tuple[int, bool]:
    """Spinal's ``x * 1000`` int16 (truncated toward zero as the C++ cast, saturated);
    returns (value, saturated)."""
    scaled = math.trunc(value * 1000.0)
    clipped = max(INT16_MIN, min(INT16_MAX, scaled))
    return clipped, clipped != scaled


def wrap_angle(a: float) -> float:
    """To (-π, π]."""
    return math.atan2(math.sin(a), math.cos(a))


def foot_wrench_rows(allocation: np.ndarray, foot_in_cog: np.ndarray) -> np.ndarray:
    """The six rows f_x, f_y, f_z, m_x, m_y, m_z (6 x N) of the wrench unit thrusts produce
    about the foot origin, foot axes: the perching QP's input on a contact plane other than
    the ceiling (``perch_params["contact_normal"]``, docs/perch.md "Contact plane")."""
    full = np.asarray(allocation, dtype=float)
    p = np.asarray(foot_in_cog, dtype=float)[:3, 3]
    forces = full[:3]
    return np.vstack([forces, full[3:] - np.cross(p, forces.T).T])


def foot_allocation(allocation: np.ndarray, foot_in_cog: np.ndarray) -> np.ndarray:
    """Q̄_foot (4 x N): rows f_z, m_x, m_y, m_z of the wrench unit thrusts produce about the
    foot origin, foot axes (= CoG axes, Sec. III). ``allocation`` is the full 6 x N Q(q);
    M_foot = M_C − p_foot × F with p_foot the foot origin in the CoG frame."""
    full = np.asarray(allocation, dtype=float)
    px, py, pz = np.asarray(foot_in_cog, dtype=float)[:3, 3].tolist()
    fx, fy, fz = full[0], full[1], full[2]
    out = np.empty((4, full.shape[1]))
    out[0] = fz
    # p x F written out: the same products and differences, in the same order, as np.cross
    out[1] = full[3] - (py * fz - pz * fy)
    out[2] = full[4] - (pz * fx - px * fz)
    out[3] = full[5] - (px * fy - py * fx)
    return out


@dataclass(frozen=True)
class ModelTerms:
    """Model quantities at one q."""

    q: np.ndarray
    mass: float
    inertia: np.ndarray
    allocation: np.ndarray  # 6 x N, CoG frame
    allocation_bar: np.ndarray  # 4 x N
    #: 4 x N about the foot origin (f_z, m_x, m_y, m_z); 6 x N (f_x .. m_z) when the perching
    #: QP's contact plane is not the ceiling (:func:`foot_wrench_rows`)
    foot_allocation: np.ndarray
    link_rotations: np.ndarray  # (N_VECTORING, 3, 3): eq. (36)'s R_i = (C<-L_i)^T
    hover_thrust: np.ndarray
    #: C<-IMU link: Spinal's ``desire_coordinate`` (its attitude is the IMU link's, the
    #: controlled frame is the CoG frame; firmware ``rot = R_est offset_rot^T``)
    imu_to_cog: np.ndarray
    #: Thrust change per unit weight share handed to the perch contact: Q̄(q)⁻¹ of
    #: [-m g, -m g p_y, m g p_x, 0] with p the contact centre in the CoG frame (the rotors
    #: shed that share of the weight and cancel the moment friction puts about the CoG);
    #: zeros without a perching controller.
    perch_unload: np.ndarray


@dataclass(frozen=True)
class Setpoint:
    position: np.ndarray  # world x, y, z
    velocity: np.ndarray
    yaw: float


@dataclass(frozen=True)
class State:
    position: np.ndarray
    velocity: np.ndarray
    yaw: float


@dataclass(frozen=True)
class ControlCommand:
    """Everything one tick sends."""

    angles: tuple[float, float, float]  # roll target, pitch target, yaw term
    base_thrust: np.ndarray
    flight_thrust: np.ndarray  # z P/I/D + feed-forward (before eq. 20's λ_perch)
    perch_thrust: np.ndarray
    perch: PerchResult | None
    alpha: tuple[float, ...]
    beta: tuple[float, ...]
    vectoring_applied: tuple[bool, ...]
    yaw_rotor: int | None


def _p_matrix_terms(g: dict) -> tuple[list[tuple[int, int, int]], list[int], bool]:
    """The pinv rows, the inertia terms (x1000 int16, :func:`to_wire`) and whether any
    saturated, of a ``gyro_compensation`` dict: rows r, p, y per rotor, then the inertia
    xx, yy, zz, xy, yz, xz."""
    columns = [np.asarray(g[k], dtype=float).tolist() for k in ("pinv_roll", "pinv_pitch")]
    columns.append(np.asarray(g["pinv_yaw"], dtype=float).tolist())
    sat = False
    rows = []
    for r, p, y in zip(*columns, strict=True):
        (a, sa), (b, sb), (c, sc) = to_wire(r), to_wire(p), to_wire(y)
        sat = sat or sa or sb or sc
        rows.append((a, b, c))
    i = np.asarray(g["inertia"], dtype=float).tolist()
    inertia = []
    for v in (i[0][0], i[1][1], i[2][2], i[0][1], i[1][2], i[0][2]):
        w, s = to_wire(v)
        sat = sat or s
        inertia.append(w)
    return rows, inertia, sat


#: ``Robot.evaluate_control``'s tuple, named as the ``evaluate`` keys it stands for
_CONTROL_KEYS = (
    "mass",
    "inertia",
    "allocation",
    "allocation_bar",
    "foot_in_cog",
    "unit_parent_rotations",
    "cog_pose",
    "imu_pose",
)


def _model_terms(*values: object) -> ModelTerms:
    """``ModelTerms(*values)`` without the frozen-dataclass ``__init__``."""
    terms = object.__new__(ModelTerms)
    terms.__dict__.update(zip(_TERMS_FIELDS, values, strict=True))
    return terms


_TERMS_FIELDS = tuple(ModelTerms.__dataclass_fields__)


def _control_command(*values: object) -> ControlCommand:
    """``ControlCommand(*values)`` without the frozen-dataclass ``__init__`` (one per tick)."""
    command = object.__new__(ControlCommand)
    command.__dict__.update(zip(_COMMAND_FIELDS, values, strict=True))
    return command


_COMMAND_FIELDS = tuple(ControlCommand.__dataclass_fields__)


class ControlPipeline:
    """Model, LQI, position, PC axes and perching for one robot (no I/O)."""

    def __init__(self, robot, config: OnboardConfig) -> None:
        self.robot = robot
        self.config = config
        self.counts: Counter[str] = Counter()
        names = list(robot.joint_names)
        units = robot.vectoring_units
        self.vectoring_joints = [
            (names.index(u["roll_joint"]), names.index(u["pitch_joint"])) for u in units
        ]
        self.thrust_max = np.array([r["thrust_max"] for r in robot.rotors], dtype=float)
        frames = list(robot.frame_names)
        if config.imu_link not in frames:
            raise ValueError(f"imu_link={config.imu_link!r}: not a frame of the robot ({frames})")
        self.lqi = LqiSynthesizer(
            None if config.lqi_q_weights is None else np.array(config.lqi_q_weights),
            None if config.lqi_r_weights is None else np.array(config.lqi_r_weights),
            clamp_gain=True,
            rotors=robot.n_rotors,
        )
        #: the synthesizer the hover flies (``lqi_q_weights``) and the one of a lost rotor's
        #: arrest (:meth:`use_arrest_gains`): Table V's weights, whose stiffer roll loop
        #: stops the turn (docs/flying.md "A lost rotor")
        self._lqi_flight = self.lqi
        self._lqi_arrest = LqiSynthesizer(
            None,
            None if config.lqi_r_weights is None else np.array(config.lqi_r_weights),
            clamp_gain=True,
            rotors=robot.n_rotors,
        )
        self.position = PositionController(**config.position_gains)
        self.pc_axes = PcAxisController()
        #: The perching QP is built for PERCH_ROTORS rotors (ASSUMPTION, docs/onboard.md): a
        #: robot with another count flies without it and its perch requests are refused.
        self.perch: PerchController | None = None
        self._foot_rows_6 = False  # the perch QP's plane is not the ceiling: 6 foot rows
        if robot.n_rotors == PERCH_ROTORS:
            # λ_rotor_max of eq. (47) defaults to the robot's rotor limit (assumption)
            perch_params = {"rotor_thrust_max": list(self.thrust_max), **config.perch_params}
            self.perch = PerchController(config.rate_hz, config.perch_cutoff_hz, **perch_params)
            self._delta_perch = np.asarray(self.perch.params()["thrust_rate_limit"], dtype=float)
            plane = self.perch.params()
            self._foot_rows_6 = plane["contact_normal"] != [0.0, 0.0, -1.0] or any(
                v != 0.0 for v in plane["contact_center"]
            )
            self._contact_center = np.asarray(plane["contact_center"], dtype=float)
        else:
            self._delta_perch = np.ones(robot.n_rotors)
        # with every rate limit > 0, max(x - limit, 0) of an all-(+0.0) array is all +0.0 again
        self._delta_positive = bool(self._delta_perch.size == robot.n_rotors) and all(
            v > 0.0 and math.isfinite(v) for v in self._delta_perch.tolist()
        )
        self._perch_zeros: np.ndarray | None = None  # perch_thrust while it is that array
        self.terms: ModelTerms | None = None
        self.gains: np.ndarray | None = None  # (N, 4, 3)
        self.gains_wire: np.ndarray | None = None  # (N, 7) int16
        #: (gains_wire, its ``rpy/gain`` payload bytes), both from the synthesis
        self.gains_payload: tuple[np.ndarray, bytes] | None = None
        self._lqi_result = None
        #: the synthesizer whose kept result lqi_result is, while not built yet (else None)
        self._lqi_result_kept = None
        self.perching = False
        self.perch_thrust = np.zeros(robot.n_rotors)
        #: share of the weight taken off the hover feed-forward while perched (the contact's
        #: friction carries it; :meth:`set_perch_weight_share`)
        self.perch_weight_share = 0.0
        self._ticks = 0
        #: the model terms and the pinv wire message depend on q alone: both are reused while
        #: the present q is bit-for-bit the one they were computed at
        self._model_key: bytes | None = None
        #: the last few q's model terms and pinv wire message: the present q flickers between
        #: a handful of servo readings, each seen again within a few ticks
        self._model_cache: dict[bytes, tuple[ModelTerms, tuple | None, bool]] = {}
        self._p_matrix: tuple[list[tuple[int, int, int]], list[int]] | None = None
        #: ``Robot.evaluate_control`` (the evaluation's arrays the pipeline reads, without
        #: every frame's pose) when the robot offers it and its ``evaluate`` is the core's;
        #: else (a robot model of another kind) its ``evaluate``
        core = _rdm.Robot
        core_evaluate = getattr(type(robot), "evaluate", None) is core.evaluate
        self._evaluate_control = (
            robot.evaluate_control
            if core_evaluate and hasattr(core, "evaluate_control") and isinstance(robot, core)
            else None
        )
        self._p_matrix_saturated = False

    # -- 1. model ------------------------------------------------------------------------
    def update_model(self, q: np.ndarray) -> bool:
        """Evaluate the model at q; on failure keep the last terms (counted)."""
        key = np.asarray(q, dtype=float).tobytes()
        if key == self._model_key:
            return True
        hit = self._model_cache.get(key)
        if hit is not None:  # the terms an evaluation at this q gives (deterministic)
            self.terms, self._p_matrix, self._p_matrix_saturated = hit
            self._model_key = key
            return True
        self._model_key = None
        self._p_matrix = None
        lean = self._evaluate_control is not None
        try:
            if lean:  # the same arrays of the same evaluation, without the rest of the dict
                o = dict(
                    zip(_CONTROL_KEYS, self._evaluate_control(q, self.config.imu_link), strict=True)
                )
            else:
                o = self.robot.evaluate(q)
        except ValueError:
            self.counts["model_error"] += 1
            return False
        qbar = np.asarray(o["allocation_bar"], dtype=float)
        full = np.asarray(o["allocation"], dtype=float)
        foot_rows = foot_wrench_rows if self._foot_rows_6 else foot_allocation
        qfoot = foot_rows(full, np.asarray(o["foot_in_cog"], dtype=float))
        rotations = np.array([np.asarray(r).T for r in o["unit_parent_rotations"]])
        if lean:
            cog_pose, imu_pose = o["cog_pose"], o["imu_pose"]
        else:
            frames = o["frames"]  # poses in the foot frame
            cog_pose, imu_pose = frames["cog"], frames[self.config.imu_link]
        cog_rot = np.asarray(cog_pose, dtype=float)[:3, :3]
        imu = cog_rot.T @ np.asarray(imu_pose, dtype=float)[:3, :3]
        g = self.config.gravity
        rhs = [o["mass"] * g, 0.0, 0.0, 0.0]
        hover = _lstsq_solution(qbar, rhs)
        unload = self._perch_unload(qbar, o["foot_in_cog"], rhs[0])
        if not (_all_finite(qbar) and _all_finite(hover) and _all_finite(unload)):
            self.counts["model_non_finite"] += 1
            return False
        values = (
            np.array(q, dtype=float),
            float(o["mass"]),
            np.asarray(o["inertia"], dtype=float),
            full,
            qbar,
            qfoot,
            rotations,
            hover,
            imu,
            unload,
        )
        self.terms = _model_terms(*values)
        self._model_key = self.terms.q.tobytes()
        self._remember_model()
        return True

    def _perch_unload(self, qbar: np.ndarray, foot_in_cog: object, weight: float) -> np.ndarray:
        """:attr:`ModelTerms.perch_unload` at this q: the friction of a contact carrying the
        weight share s acts up (+z of the CoG frame, level when perched) at the contact centre
        p, so the rotors give (1 - s) m g and the moment -p x (0, 0, s m g)."""
        if self.perch is None:
            return np.zeros(qbar.shape[1])
        pose = np.asarray(foot_in_cog, dtype=float)
        p = pose[:3, :3] @ self._contact_center + pose[:3, 3]
        return _lstsq_solution(qbar, [-weight, -weight * p[1], weight * p[0], 0.0])

    def _remember_model(self) -> None:
        """Keep the present terms (and pinv message, if built) under the present q."""
        if self._model_key is None or self.terms is None:
            return
        cache = self._model_cache
        cache.pop(self._model_key, None)
        cache[self._model_key] = (self.terms, self._p_matrix, self._p_matrix_saturated)
        while len(cache) > MODEL_CACHE_SIZE:
            del cache[next(iter(cache))]  # the oldest

    def desire_coordinate(self) -> tuple[float, float, float] | None:
        """ZYX (roll, pitch, yaw) of C<-IMU link, the firmware's ``from_euler`` order, so that
        Spinal estimates and controls the CoG frame's attitude whatever q is."""
        t = self.terms
        if t is None:
            return None
        r = t.imu_to_cog
        roll = math.atan2(r[2, 1], r[2, 2])
        pitch = -math.asin(max(-1.0, min(1.0, r[2, 0])))
        yaw = math.atan2(r[1, 0], r[0, 0])
        return roll, pitch, yaw

    # -- 2. LQI --------------------------------------------------------------------------
    def synthesize_due(self) -> bool:
        return self._ticks % self.config.lqi_every == 0

    @property
    def lqi_result(self):
        """The :class:`~rdm.control.lqi.LqiResult` of the last successful synthesis (None
        before one)."""
        kept = self._lqi_result_kept
        if kept is not None:
            self._lqi_result, self._lqi_result_kept = kept.kept_result(), None
        return self._lqi_result

    @lqi_result.setter
    def lqi_result(self, value) -> None:
        self._lqi_result, self._lqi_result_kept = value, None

    def synthesize(self) -> bool:
        """LQI gains at the current model; on failure keep the last good ones (counted). The
        gains, their ``rpy/gain`` wire terms and payload and the finite / fell-back / clamped
        flags come from :meth:`LqiSynthesizer.synthesize_wire`; :attr:`lqi_result` is built
        when read."""
        t = self.terms
        if t is None:
            return False
        try:
            gains, wire, payload, finite, fell_back, clamped = self.lqi.synthesize_wire(
                t.mass, t.inertia, t.allocation_bar
            )
        except ValueError:
            wire = None
        if wire is None:  # the solve or the wire terms failed
            self.counts["lqi_failed"] += 1
            self.lqi.reset()  # next attempt is cold
            return False
        if not finite:
            self.counts["lqi_failed"] += 1
            return False
        self.counts["lqi_ok"] += 1
        if fell_back:
            self.counts["lqi_fell_back"] += 1
        if clamped:
            self.counts["gain_clamped"] += 1
        self._lqi_result, self._lqi_result_kept = None, self.lqi
        self.gains = gains
        self.gains_wire = wire
        self.gains_payload = (wire, payload)
        return True

    def use_arrest_gains(self, arrest: bool) -> bool:
        """Synthesize with Table V's LQI weights (``arrest``: a lost rotor's arrest) or with
        the configured ones again; on a switch the gains are synthesized at once (True: new
        gains to send). ASSUMPTION: Table V's lightly damped 12 Hz roll mode does not matter
        for the arrest's 0.1 s."""
        want = self._lqi_arrest if arrest else self._lqi_flight
        if self.lqi is want:
            return False
        self.lqi = want
        want.reset()  # a cold start: the other weights' solution is no warm start
        return self.synthesize()

    def p_matrix_wire(self) -> tuple[list[tuple[int, int, int]], list[int]] | None:
        """``p_matrix_pseudo_inverse_inertia``: pinv(Q̄) columns r, p, y per rotor and the
        inertia xx, yy, zz, xy, yz, xz, all x1000 int16."""
        t = self.terms
        if t is None:
            return None
        if self._p_matrix is not None:
            if self._p_matrix_saturated:
                self.counts["pinv_saturated"] += 1
            return self._p_matrix
        try:
            g = gyro_compensation(t.allocation_bar, t.inertia)
        except ValueError:
            self.counts["pinv_failed"] += 1
            return None
        rows, inertia, sat = _p_matrix_terms(g)
        if sat:
            self.counts["pinv_saturated"] += 1
        if self._model_key is not None:  # the terms are the ones at the keyed q
            self._p_matrix, self._p_matrix_saturated = (rows, inertia), sat
            self._remember_model()
        return rows, inertia

    # -- 3-5. one control step -------------------------------------------------------------
    def set_perching(self, on: bool) -> None:
        """Enter (``on``) or leave the perching mode; without a perching controller (a robot
        of another rotor count than PERCH_ROTORS) entering is refused and counted."""
        if on and self.perch is None:
            self.counts["perch_unavailable"] += 1
            return
        if on and not self.perching:
            self.perch.reset(np.zeros(self.robot.n_rotors))
            self.position.reset()  # the horizontal loop is held while perched (see step)
            self.counts["perch_entered"] += 1
        self.perching = on

    def set_perch_weight_share(self, share: float) -> None:
        """While perched, add ``share`` x :attr:`ModelTerms.perch_unload` to the hover
        feed-forward: the rotors' thrust drops by that share of the weight, the contact's
        friction carries it, and the rotors cancel the moment it puts about the CoG (a wall
        perch, docs/scenarios.md "wall-perching"). Bounded to [0, ``PERCH_WEIGHT_SHARE_MAX``];
        a non-finite value is refused (share kept) and an out-of-range one clipped, both
        counted. Off the contact (not perching) the feed-forward is the full hover thrust."""
        if not math.isfinite(share):
            self.counts["perch_weight_share_refused"] += 1
            return
        bounded = min(max(float(share), 0.0), PERCH_WEIGHT_SHARE_MAX)
        if bounded != share:
            self.counts["perch_weight_share_clipped"] += 1
        self.perch_weight_share = bounded

    def set_position_gains(self, gains: dict, bumpless: bool = False) -> None:
        """Replace the position controller's gains (keyword overrides of
        :class:`PositionController`, as ``OnboardConfig.position_gains``): a gain schedule per
        flight posture, as JSK's dynamic reconfigure. The new controller's integral starts at
        0, or with ``bumpless`` carries the old one's integral action ``k_I ∫e`` (no jump of
        the target tilt at the switch)."""
        new = PositionController(**gains)
        if bumpless:
            new.take_integral_action(self.position)
        self.position = new
        self.counts["position_gains_set"] += 1

    def reset_integrators(self) -> None:
        self.position.reset()
        self.pc_axes = PcAxisController()

    def step(
        self,
        state: State,
        setpoint: Setpoint,
        joint_targets: np.ndarray,
        foot_wrench: np.ndarray | None,
        dt: float,
    ) -> ControlCommand | None:
        """One tick; None if there is no model or no gains yet (nothing to command)."""
        self._ticks += 1
        t, gains = self.terms, self.gains
        if t is None or gains is None:
            self.counts["not_ready"] += 1
            return None
        n_rot = self.robot.n_rotors
        ff = t.hover_thrust if self.config.feed_forward == "hover" else np.zeros(n_rot)
        if self.perching and self.perch_weight_share > 0.0:
            ff = ff + self.perch_weight_share * t.perch_unload
        axes = self._flight_axes(state, setpoint, joint_targets, ff, dt)
        if axes[6]:
            self.counts["vectoring_singular"] += axes[6]
        roll, pitch, yaw_term, alpha, beta, applied, _, flight, yaw_rotor = axes
        result = None
        if self.perching and self.perch is not None:
            w = foot_wrench if foot_wrench is not None else np.full(6, np.nan)
            if foot_wrench is None:
                self.counts["perch_no_foot_sample"] += 1
            result = self.perch.tick(w, t.foot_allocation, t.allocation_bar, t.mass)
            self.counts[f"perch_{result.status}"] += 1
            self.perch_thrust = np.asarray(result.thrust, dtype=float)
        else:
            # eq. (48)'s rate limit also on the way out of perching (assumption)
            if self.perch_thrust is not self._perch_zeros or not self._delta_positive:
                self.perch_thrust = np.maximum(self.perch_thrust - self._delta_perch, 0.0)
                if self._delta_positive and max(self.perch_thrust.tolist(), default=1.0) == 0.0:
                    self._perch_zeros = self.perch_thrust  # all +0.0: stays so (see __init__)
        total = flight + self.perch_thrust
        if self.config.clip_base_thrust:
            total = _clip(total, 0.0, self.thrust_max)
        if not _all_finite(total):  # cannot happen with finite inputs; never send NaN
            self.counts["non_finite_command"] += 1
            return None
        return _control_command(
            (roll, pitch, yaw_term),
            total,
            flight,
            self.perch_thrust.copy(),
            result,
            alpha,
            beta,
            applied,
            yaw_rotor,
        )

    def _flight_axes(
        self,
        state: State,
        setpoint: Setpoint,
        joint_targets: np.ndarray,
        feed_forward: np.ndarray,
        dt: float,
    ) -> tuple:
        """Position loop (eqs. 30-36), vectoring choice and PC-side axes of :meth:`step` in
        one Rust call (``_rdm.flight_axes``): roll, pitch, yaw term, alpha, beta, applied,
        the number of singular units (the caller counts them), the base thrust, the yaw
        rotor.

        Perched, the foot cannot translate: the horizontal loop is held at zero error (φ_d =
        θ_d = 0, vectoring level; its integral is cleared on entry, see set_perching), and
        the altitude loop too (zero error, integral kept: λ_flight keeps carrying the weight
        and λ_perch alone presses the plate, eq. 20). ASSUMPTION (the paper's Fig. 6 shows
        no position loop when perched). A ValueError, with nothing stepped, for an input the
        call cannot take (a joint vector the units' indices do not fit, a non-finite
        setpoint, dt <= 0); errors of the controllers are raised as they raise them."""
        t = self.terms
        assert t is not None
        axes = _rdm.flight_axes(
            self.position._core,
            self.pc_axes,
            self.gains,
            np.asarray(state.position, dtype=float),
            np.asarray(state.velocity, dtype=float),
            state.yaw,
            np.asarray(setpoint.position, dtype=float),
            np.asarray(setpoint.velocity, dtype=float),
            setpoint.yaw,
            t.link_rotations,
            np.asarray(joint_targets, dtype=float),
            self.vectoring_joints,
            np.asarray(feed_forward, dtype=float),
            self.perching,
            self.config.vectoring,
            self.config.vectoring_min_nz,
            dt,
        )
        if axes is None:
            raise ValueError(
                "flight axes: joint targets must cover the vectoring joints, the setpoint be "
                "finite and dt > 0"
            )
        return axes
