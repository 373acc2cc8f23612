"""The Rust timing loops of `rdm bench` time the real computation: they return the
requested number of positive samples, and what each timed step computed equals the
ordinary bindings' results on the same inputs (and, for LQI and the QP, independent
oracles: scipy's CARE and clarabel's Python wheel)."""

from __future__ import annotations

import numpy as np
import pytest

from rdm import _rdm
from rdm.bench import peers
from rdm.bench import scenarios as sc
from rdm.control.lqi import TABLE_V_Q, TABLE_V_R, LqiSynthesizer
from rdm.control.perch import PerchController
from rdm.control.position import PositionController


def test_spinal_loop_matches_the_binding() -> None:
    n = 400
    si = sc.spinal_inputs(n)
    r = _rdm.time_spinal_steps(
        si.gains, si.pinv, si.inertia, si.now, si.gyro, si.acc, si.mag, si.voltage,
        si.command_every, si.command_angles, si.command_base_thrust,
    )  # fmt: skip
    assert r["ns"].shape == (n,) and r["ns"].dtype == np.int64
    assert np.all(r["ns"] > 0)
    assert r["invalid"] == 0
    s = sc.python_spinal(si)
    duty, thrust, euler = [], [], []
    for k in range(n):
        if k % si.command_every == 0:
            s.four_axis_command(list(si.command_angles), si.command_base_thrust, si.now[k])
        out = s.step(si.now[k], si.gyro[k], si.acc[k], si.mag[k], si.voltage)
        duty.append(out.duty)
        thrust.append(out.thrust)
        euler.append(out.euler)
    assert out.status == "armed"
    np.testing.assert_array_equal(r["duty"], np.array(duty))
    np.testing.assert_array_equal(r["thrust"], np.array(thrust))
    np.testing.assert_array_equal(r["euler"], np.array(euler))
    # The comparison means something: the controller is flying, outputs move.
    assert np.ptp(r["thrust"][:, 0]) > 1e-3 and np.ptp(r["euler"][:, 0]) > 1e-4


@pytest.mark.parametrize("warm", [True, False])
def test_lqi_loop_matches_the_binding_and_scipy(warm: bool) -> None:
    from scipy.linalg import solve_continuous_are

    n = 60
    li = sc.lqi_inputs(n)
    r = _rdm.time_lqi_synthesis(li.masses, li.inertias, li.allocations, warm)
    assert r["ns"].shape == (n,) and np.all(r["ns"] > 0)
    assert r["failures"] == 0
    synth = LqiSynthesizer()
    for k in range(n):
        if not warm:
            synth.reset()
        k_py = synth.synthesize(li.masses[k], li.inertias[k], li.allocations[k]).k
        np.testing.assert_array_equal(r["k"][k], k_py)
    # Independent oracle on a few configurations along the trajectory.
    for k in (0, n // 2, n - 1):
        a, b = _rdm.augmented_system(li.masses[k], li.inertias[k], li.allocations[k])
        q, rr = np.diag(TABLE_V_Q), np.diag(TABLE_V_R)
        p = solve_continuous_are(a, b, q, rr)
        k_ref = -np.linalg.solve(rr, b.T @ p)
        np.testing.assert_allclose(r["k"][k], k_ref, rtol=1e-7, atol=1e-7 * np.abs(k_ref).max())


def test_onboard_tick_loop_matches_the_bindings_and_clarabel() -> None:
    n = 300
    ti = sc.tick_inputs(n)
    r = _rdm.time_onboard_ticks(
        ti.position, ti.velocity, ti.target_position, ti.target_velocity, ti.target_yaw,
        ti.link_rotations, ti.dt, ti.foot_wrench, ti.foot_allocation, ti.allocation, ti.mass,
        ti.initial_thrust,
    )  # fmt: skip
    assert r["ns"].shape == (n,) and np.all(r["ns"] > 0)
    assert r["failures"] == 0 and r["position_failures"] == 0
    assert {r["status_names"][s] for s in r["status"]} <= {"solved", "almost_solved"}
    position, perch = PositionController(), PerchController()
    perch.reset(ti.initial_thrust)
    problems = []
    for k in range(n):
        cmd = position.step(
            ti.position[k], ti.velocity[k], ti.target_position[k], ti.target_velocity[k],
            ti.target_yaw[k], ti.link_rotations[k], ti.dt,
        )  # fmt: skip
        res = perch.tick(ti.foot_wrench[k], ti.foot_allocation[k], ti.allocation[k], ti.mass)
        np.testing.assert_array_equal(r["thrust"][k], res.thrust)
        np.testing.assert_array_equal(r["alpha"][k], cmd.alpha)
        np.testing.assert_array_equal(r["beta"][k], cmd.beta)
        np.testing.assert_array_equal(r["acceleration"][k], cmd.acceleration)
        p = perch.problem_data()
        problems.append(
            peers.QpData(p.P, p.q, p.A, p.b, p.zero_cone, p.nonnegative_cone,
                         p.variable_scale, res.thrust)
        )  # fmt: skip
    # The perching thrusts move and stay off their bounds (the QP is not trivial) ...
    assert np.ptp(r["thrust"][50:, 0]) > 0.1 and np.all(r["thrust"][50:, :2] > 0.1)
    # ... and agree with clarabel's Python wheel on the very same QPs.
    oracle = peers.run_clarabel(problems, update=False)
    assert oracle.failures == 0
    # The core's default active-set answer is exact; an interior point at gap 1e-8 sits
    # ~sqrt(gap) off a weakly active bound (λ = 0): ≤ sqrt(2e-8) * 30 N ≈ 4.2e-3 N (docs/perch.md).
    assert oracle.max_error < 5e-3


def test_timing_loops_name_bad_arguments() -> None:
    li = sc.lqi_inputs(5)
    with pytest.raises(_rdm.RdmError, match="inertias"):
        _rdm.time_lqi_synthesis(li.masses, li.inertias[:4], li.allocations, True)
    si = sc.spinal_inputs(5)
    with pytest.raises(_rdm.RdmError, match="gyro"):
        _rdm.time_spinal_steps(
            si.gains, si.pinv, si.inertia, si.now, si.gyro[:3], si.acc, si.mag, si.voltage,
            5, si.command_angles, si.command_base_thrust,
        )  # fmt: skip


def test_build_profile_and_timer() -> None:
    assert _rdm.bench_build_profile() in ("release", "debug")
    ns = np.asarray(_rdm.time_timer_overhead(100))
    assert ns.shape == (100,) and np.all(ns >= 0)
