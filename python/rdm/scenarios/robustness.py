"""The perching experiment over randomized conditions (``rdm sim perching-hanging --randomize N``).

Run ``k`` draws its conditions from seed ``k`` (and runs the stack with that seed): what a lab
cannot know exactly about its robot and room. The plant changes; the onboard node keeps the
nominal model and gains, so every draw is a model error the controllers must absorb.

ASSUMPTIONS (ranges, uniform unless said): friction of the ceiling and the foot plate x
[0.7, 1.3] of Table VII's; every body's mass x [0.95, 1.05] (one factor); the root link's CoG
moved by up to 5 mm in x and z (not in y: the simulated robot rests on the floor on a line of
contact along its links, and a CoG 0.2 mm off that line tips it 7.7 deg before take-off,
from where the take-off flips it: a limit of the simulated landing contact,
docs/scenarios.md "Perching over randomized conditions"); joint servo stiffness kp x
[0.7, 1.3] (kv kept); motion capture on the marker body with 5-25 ms latency and 1-3 x the
nominal noise (:class:`rdm.scenarios.mocap_node.MocapSensor`); battery 22.8-25.2 V (3.8-4.2 V
per cell).

A run succeeds when every metric of the perching scenario passes (perched, contact kept, slip
under 1 mm, normal force, friction cone, ZMP off the plate edge). The campaign reports the
success rate with the number of runs behind it, and the margins as distributions.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from concurrent.futures import Executor
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from rdm.json_values import nulled

from .seed_sweep import run_calls

#: The perching metrics whose spread the report shows (name in the scenario's summary).
MARGINS = (
    "min normal force while perched",
    "max friction-cone usage |F_t|/(mu F_z)",
    "foot slip while perched",
    "min ZMP margin to the plate edge",
)


@dataclass(frozen=True)
class Conditions:
    """One draw of the randomized conditions."""

    friction_scale: float
    mass_scale: float
    cog_offset_m: tuple[float, float, float]
    servo_kp_scale: float
    mocap_latency_s: float
    mocap_noise_scale: float
    battery_voltage: float


def draw(seed: int) -> Conditions:
    """The conditions of run ``seed`` (a reproducible draw)."""
    rng = np.random.default_rng([seed, 0x5EED])
    return Conditions(
        friction_scale=float(rng.uniform(0.7, 1.3)),
        mass_scale=float(rng.uniform(0.95, 1.05)),
        cog_offset_m=(float(rng.uniform(-0.005, 0.005)), 0.0, float(rng.uniform(-0.005, 0.005))),
        servo_kp_scale=float(rng.uniform(0.7, 1.3)),
        mocap_latency_s=float(rng.uniform(0.005, 0.025)),
        mocap_noise_scale=float(rng.uniform(1.0, 3.0)),
        battery_voltage=float(rng.uniform(22.8, 25.2)),
    )


class _Scene:
    """``StackOptions.scene``: the draw's friction, masses and CoG on the MuJoCo spec
    (a class, so it pickles to a worker process)."""

    def __init__(self, c: Conditions) -> None:
        self.c = c

    def __call__(self, spec: Any) -> None:
        from rdm.plant.mjcf import CEILING_GEOM

        for geom in (spec.geom(CEILING_GEOM), spec.geom("foot_plate_box")):
            f = list(geom.friction)
            geom.friction = [f[0] * self.c.friction_scale, f[1] * self.c.friction_scale, f[2]]
        for body in spec.bodies:
            if body.name != "world":
                body.mass = body.mass * self.c.mass_scale
        root = spec.body("root_link")
        root.ipos = [p + d for p, d in zip(root.ipos, self.c.cog_offset_m, strict=True)]


def run_drawn(base: str, seed: int, duration: float | None, replace: bool) -> dict[str, Any]:
    """The perching run of draw ``seed`` into ``base``; its conditions, metrics, success (or
    the error that stopped it). Never raises."""
    from rdm.plant.servo import ServoParams
    from rdm.sim.run_folder import run_folders

    from . import perching
    from .mocap_node import MocapSensor
    from .stack import StackOptions

    c = draw(seed)
    nominal = StackOptions().servo or ServoParams()
    out: dict[str, Any] = {"seed": seed, "conditions": asdict(c)}
    try:
        nominal_mocap = MocapSensor()
        with run_folders(replace=replace):
            result = perching.run(
                base,
                duration=perching.DEFAULT_DURATION if duration is None else duration,
                seed=seed,
                scene=_Scene(c),
                servo=ServoParams(kp=nominal.kp * c.servo_kp_scale, kv=nominal.kv),
                mocap=MocapSensor(
                    position_noise_m=nominal_mocap.position_noise_m * c.mocap_noise_scale,
                    rotation_noise_rad=nominal_mocap.rotation_noise_rad * c.mocap_noise_scale,
                    latency_s=c.mocap_latency_s,
                ),
                battery_voltage=c.battery_voltage,
            )
        out["success"] = bool(result.all_passed)
        out["metrics"] = {m.name: m.ours for m in result.metrics}
        out["failed_metrics"] = [m.name for m in result.metrics if m.passed is False]
        out["folder"] = str(result.folder)
    except Exception as exc:  # a run that fails is a row of the report
        out["success"] = False
        out["error"] = f"{type(exc).__name__}: {exc}"
    return out


def randomized(
    base: str | os.PathLike[str],
    seeds: Sequence[int],
    duration: float | None = None,
    executor: Executor | None = None,
    progress: Callable[[dict[str, Any]], None] | None = None,
    replace: bool = False,
) -> list[dict[str, Any]]:
    """One perching run per seed on ``executor`` (default: a process per core; a Ray or Dask
    ``concurrent.futures`` executor scales it out); the runs in seed order."""
    calls = [(run_drawn, str(base), int(s), duration, replace) for s in seeds]
    return run_calls(calls, executor, progress)


def summarize(runs: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """Success rate with its run count, each margin's distribution, the failed draws."""
    margins = {}
    for name in MARGINS:
        v = np.array([r["metrics"].get(name, np.nan) for r in runs if "metrics" in r], float)
        v = v[np.isfinite(v)]
        margins[name] = (
            {
                "n": int(v.size),
                "median": float(np.median(v)),
                "p10": float(np.percentile(v, 10)),
                "p90": float(np.percentile(v, 90)),
                "min": float(v.min()),
                "max": float(v.max()),
            }
            if v.size
            else {"n": 0}
        )
    succeeded = sum(1 for r in runs if r["success"])
    return nulled(
        {
            "scenario": "perching-hanging",
            "runs": len(runs),
            "succeeded": succeeded,
            "success_rate": succeeded / len(runs) if runs else None,
            "margins": margins,
            "failed": [
                {
                    "seed": r["seed"],
                    "conditions": r["conditions"],
                    "error": r.get("error"),
                    "failed_metrics": r.get("failed_metrics", []),
                }
                for r in runs
                if not r["success"]
            ],
            "per_run": list(runs),
        }
    )


def plot(doc: dict[str, Any], out: Path) -> None:
    """One panel per margin: its value against the friction draw, failed runs marked."""
    from rdm.sim.plot_worker import pyplot

    plt = pyplot()
    fig, axes = plt.subplots(1, len(MARGINS), figsize=(4 * len(MARGINS), 3.2))
    runs = [r for r in doc["per_run"] if r.get("metrics")]
    mu = [r["conditions"]["friction_scale"] for r in runs]
    for ax, name in zip(axes, MARGINS, strict=True):
        y = [r["metrics"].get(name) for r in runs]
        ok = [r["success"] for r in runs]
        ax.scatter(
            [m for m, s in zip(mu, ok, strict=True) if s],
            [v for v, s in zip(y, ok, strict=True) if s],
            s=12,
            label="success",
        )
        ax.scatter(
            [m for m, s in zip(mu, ok, strict=True) if not s],
            [v for v, s in zip(y, ok, strict=True) if not s],
            s=18,
            marker="x",
            color="r",
            label="failed",
        )
        ax.set_xlabel("friction x Table VII")
        ax.set_title(name, fontsize=8)
    axes[0].legend(fontsize=7)
    fig.suptitle(f"perching over randomized conditions: {doc['succeeded']}/{doc['runs']} succeed")
    fig.tight_layout()
    fig.savefig(out, dpi=100)
    plt.close(fig)
