"""``hover``: take-off and hover through every wire."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from rdm.sim import Metric
from rdm.sim.plots import plot_panels

from .common import ScenarioResult, finish, roll_pitch, run_stack, sim_stack_options, truth_arrays
from .stack import Stack, build_stack

ARM_AT = 1.5  # s: the CAN master runs from ~1.4 s (100 ms boot delay + enumeration)
HOVER_Z = 0.4  # m: CoG target height
DEFAULT_DURATION = 6.0


def make_script(target: np.ndarray, after_servo_states: bool = False):
    """Arms at ARM_AT and sets the hover target; ``after_servo_states``: not before the
    onboard node has Spinal's first ``servo/states`` (its CAN master has enumerated every
    Neuron, which takes longer the more Neurons the robot has)."""

    def script(stack: Stack, now: float) -> None:
        if now >= ARM_AT and not getattr(stack, "_armed", False):
            if after_servo_states and stack.onboard.servo_states_at is None:
                return
            stack._armed = True  # type: ignore[attr-defined]
            stack.onboard.set_target(target, 0.0)
            stack.onboard.arm()

    script.kernel_touches = ()  # type: ignore[attr-defined]  # only the onboard node
    return script


def run(
    base: str | Path,
    duration: float = DEFAULT_DURATION,
    seed: int = 0,
    uart: str = "inproc",
    speed: float | None = None,
    robot: str = "rdm",
) -> ScenarioResult:
    """``robot``: a shipped name or the path of a robot TOML (any rotor count 1..8).
    ASSUMPTION: a robot other than the shipped RDM arms at ARM_AT or at Spinal's first
    ``servo/states``, whichever is later (the six-rotor test robot's six Neurons report at
    2.1 s; armed before, its integrators wind up on the floor with the motors still idle and
    it tips at take-off); the shipped RDM arms at ARM_AT (its four Neurons report 25 ms
    later), the timing its reference bytes hold."""
    opts = replace(sim_stack_options(seed, uart, speed=speed), robot=robot)
    target = np.array([0.483, 0.0, HOVER_Z])
    stack = build_stack("hover", base, opts, make_script(target, robot != "rdm"))
    wall = run_stack(stack, duration)
    a = truth_arrays(stack)
    window = a["t"] >= max(ARM_AT + 2.5, duration - 2.0)
    err = a["cog"][window] - target if window.any() else np.full((1, 3), np.nan)
    rp = roll_pitch(a["quat"])
    metrics = [
        Metric(
            "hover position RMSE (last 2 s)",
            float(np.sqrt(np.mean(np.sum(err**2, 1)))),
            None,
            "m",
            "max",
            limit=0.15,
        ),
        Metric(
            "max |roll|,|pitch| after take-off",
            float(np.degrees(np.abs(rp[a["t"] > ARM_AT]).max()))
            if (a["t"] > ARM_AT).any()
            else float("nan"),
            None,
            "deg",
            "max",
            limit=20.0,
        ),
        Metric("final CoG height", float(a["cog"][-1, 2]), HOVER_Z, "m", "near", tol=0.15),
    ]
    plot_panels(
        stack.folder.plot("hover"),
        a["t"],
        [
            ("CoG position", {"x": a["cog"][:, 0], "y": a["cog"][:, 1], "z": a["cog"][:, 2]}, "m"),
            ("attitude", {"roll": np.degrees(rp[:, 0]), "pitch": np.degrees(rp[:, 1])}, "deg"),
            (
                "rotor thrust",
                {f"rotor{i + 1}": a["thrust"][:, i] for i in range(a["thrust"].shape[1])},
                "N",
            ),
        ],
        title="hover through the wires",
    )
    return finish(ScenarioResult("hover", stack, metrics), duration, wall)
