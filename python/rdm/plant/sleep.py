"""The robot at rest sleeps in MuJoCo, and its own commands wake it.

MuJoCo (``mjENBL_SLEEP``, in recent releases such as the 4.0 used here) can put a kinematic
tree to sleep once its velocity has stayed under ``opt.sleep_tolerance`` for a few steps, and
then skips its dynamics, collisions and sensors until something wakes it: a contact with an
awake body, an applied force (``xfrc_applied``, ``qfrc_applied``) or its sleep policy. It does
not watch ``ctrl``, so by default MuJoCo never lets an actuated tree sleep.
:class:`RestingSleep` adds that watch for the robot: in each step, after the plant has written
this step's controls (rotor thrusts after the ESC lag, servo goals), the policy of the robot's
trees is "allowed" when every control is the same as in the last step and every rotor is
stopped (thrust 0), and "never" otherwise. A changed control finds the robot awake in that same
step: if it slept, ``mj_step1`` runs again on the same state, which wakes it and redoes the
position stages, before ``mj_step2``.

So the robot sleeps only while it rests with its rotors stopped and nothing commanded: on the
floor during the boot. That is where it saves most. It never sleeps perched (its rotors press
the plate; a sleeping tree has no contacts, so the perch's ground truth would lose them). The
sleeping robot is frozen, where the awake one keeps settling by ~1e-5 rad. Every other tree
(the tasks' objects) keeps the policy "never": they are moved by hand, which would not wake
them.

ASSUMPTION (docs/plant.md "Sleeping at rest"): a tolerance of 1e-5 (MuJoCo's
velocity norm weighted by the dof lengths; its default is 1e-3). With the default the robot
fell asleep 65 ms sooner while a joint still crept, and at the end of the boot it stood 1e-4
rad from the never-sleeping robot; with 1e-5 the difference is 1e-5.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable

import mujoco
import numpy as np

from rdm._rdm import RestingSleepCore

_SLEEP_BIT = getattr(mujoco.mjtEnableBit, "mjENBL_SLEEP", None)
_POLICY = getattr(mujoco, "mjtSleepPolicy", None)

#: Whether this MuJoCo can put trees to sleep.
SLEEP_AVAILABLE = _SLEEP_BIT is not None and _POLICY is not None
#: ``mjENBL_SLEEP`` of ``opt.enableflags`` (0 on a MuJoCo without sleeping).
SLEEP_ENABLE_BIT = int(_SLEEP_BIT) if _SLEEP_BIT is not None else 0
#: The bit the rule switches in ``opt.enableflags`` (read when a :class:`RestingSleep` is made).
_SLEEP_ENABLE = SLEEP_ENABLE_BIT
ALLOWED = int(_POLICY.mjSLEEP_ALLOWED) if _POLICY is not None else -1
NEVER = int(_POLICY.mjSLEEP_NEVER) if _POLICY is not None else -1
#: ``opt.sleep_tolerance`` of a plant with :class:`RestingSleep` (see the module docstring).
SLEEP_TOLERANCE = 1e-5


class RestingSleep:
    """Sleep of the robot's trees (``trees``) while its controls stay the same.

    MuJoCo's sleeping itself (``mjENBL_SLEEP``) is on only while it can matter: while the
    policy is "allowed", and for one step after "never" is written (MuJoCo resets the robot's
    countdown to sleep in it). In flight the robot cannot sleep, and MuJoCo's per-object
    sleep checks (``mj_sleepState`` for every actuator and sensor, ~2.6k instructions a step)
    are skipped; the numbers are the same (docs/plant.md "Sleeping at rest").

    The rule and its state (the last controls, ``pending``, ``allowed``, ``wakes``,
    ``sleep_on``, ``settled``) live in one Rust object, ``rdm._rdm.RestingSleepCore``
    (``rdm_core::sim::resting_sleep``), on MuJoCo's own arrays; the lockstep kernel's plant
    step calls the same object.
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        data: mujoco.MjData,
        trees: Iterable[int],
        rotors: Iterable[int],
    ) -> None:
        if not SLEEP_AVAILABLE:
            raise RuntimeError(f"MuJoCo {mujoco.__version__} cannot put trees to sleep")
        self.trees = sorted({int(t) for t in trees if t >= 0})
        if not self.trees:
            raise ValueError("RestingSleep: no tree to put to sleep")
        #: The rotor actuators (``ctrl`` indices): the robot sleeps only with all of them at 0.
        self.rotors = [int(r) for r in rotors]
        model.opt.enableflags |= int(_SLEEP_BIT)
        model.opt.sleep_tolerance = SLEEP_TOLERANCE
        model.tree_sleep_policy[:] = NEVER  # only the robot may sleep (allowed by the rule)
        #: The rule and its state (MuJoCo's sleeping on, the policy "never", the next step
        #: counted as changed).
        self._core = RestingSleepCore(
            self.trees,
            self.rotors,
            ALLOWED,
            NEVER,
            _SLEEP_ENABLE,
            data.ctrl,
            model.tree_sleep_policy,
            data.tree_asleep,
            model.opt,
        )

    @property
    def pending(self) -> bool:
        """The next step counts as changed (start, reset, an outside change of the state)."""
        return self._core.pending

    @property
    def allowed(self) -> bool:
        """The policy now written for the trees ("allowed" True, "never" False)."""
        return self._core.allowed

    @property
    def wakes(self) -> int:
        """Steps that found the robot asleep and woke it for a changed control."""
        return self._core.wakes

    @property
    def sleep_on(self) -> bool:
        """``mjENBL_SLEEP`` is set now."""
        return self._core.sleep_on

    @property
    def settled(self) -> bool:
        """A step ran with "never" and sleeping on since the policy was last "allowed" (the
        robot's countdown to sleep is reset): sleeping may go off."""
        return self._core.settled

    @property
    def last_ctrl(self) -> np.ndarray:
        """The controls of the last step (a copy)."""
        return self._core.last_ctrl

    def asleep(self) -> bool:
        """Whether a robot tree is asleep."""
        return self._core.asleep()

    def wake_next(self) -> None:
        """Treat the next step as changed (the caller may have changed the state)."""
        self._core.wake_next()

    def before_step2(self, step1: Callable[[], None]) -> None:
        """This step's rule, once its controls are written: allowed if they equal the last
        step's and the rotors are stopped, else never, and a sleeping robot woken now
        (``step1`` on the same state); then MuJoCo's sleeping on or off for ``mj_step2``."""
        self._core.before_step2(step1)
