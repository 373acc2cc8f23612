"""``perching`` (the paper's posture, the default scenario) end to end: the robot flown is
the foot-at-plate description, the perching QP runs with Table VII's parameters, and every
metric row is recomputed here from the raw per-tick records (MuJoCo ground truth and the
scenario's rotor probe) with numpy written apart from the scenario's code, and the perch's
measured state is held against the figures of docs/scenarios.md with margins a regression
crosses. One default run (64 s simulated, ``log=False``)."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET

import mujoco
import numpy as np
import pytest

from rdm.descriptions import FOOT_AT_PLATE, ROOT_LINK_LENGTH, ROTOR_DIAMETER
from rdm.model import shipped_robot_files
from rdm.scenarios import SCENARIOS, perching
from rdm.scenarios import perching_foot_at_plate as fp
from rdm.scenarios.common import truth_arrays

pytestmark = pytest.mark.timeout(600)


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    res = fp.run(tmp_path_factory.mktemp("foot_at_plate"), log=False)
    rows = {m.name: m for m in res.metrics}
    return res, rows, res.script.arrays(), truth_arrays(res.stack)


def test_registered_as_perching_beside_the_hanging_variant():
    """Bug caught: ``perching`` pointing at the hanging scenario's run, or the two swapped."""
    sc = SCENARIOS["perching"]
    assert sc.run is fp.run
    assert sc.default_duration == fp.DEFAULT_DURATION
    assert SCENARIOS["perching-hanging"].run is perching.run


def test_arm_motion_has_the_hanging_goals_at_fig10_timing():
    """The variant's arm motion: the hanging scenario's goals, 10 s per segment (Fig. 10's
    52-62 s episode), after 10 s perched at rest, and the default run long enough for a hold
    after it (contact near 15 s + settle + motion). Bugs caught: the 3 s segments of
    ``perching.PERCHED_MOTION`` kept, a goal dropped or reordered, the hanging scenario's
    1.5 s settle kept, a duration that ends inside the motion."""
    assert [d for d, _ in fp.FOOT_PLATE_MOTION] == [10.0, 10.0, 10.0]
    assert [g for _, g in fp.FOOT_PLATE_MOTION] == [g for _, g in perching.PERCHED_MOTION]
    assert fp.SETTLE_S == 10.0 and fp.TIMING.settle_s == fp.SETTLE_S
    assert fp.DEFAULT_DURATION > 15.0 + fp.SETTLE_S + 30.0 + 5.0


def test_the_shipped_description_puts_the_foot_unit_at_the_plate():
    """From the URDF text (xml parser, not the generator): the joint carrying the foot unit's
    roll stage sits 0.04 m along the root link. Bug caught: the data file generated with the
    far-tip foot unit (0.40 m) or a stale copy."""
    with shipped_robot_files(fp.ROBOT) as (urdf, _):
        root = ET.parse(urdf).getroot()
    joint = next(j for j in root.iter("joint") if j.get("name") == "alpha1")
    xyz = [float(v) for v in joint.find("origin").get("xyz").split()]
    assert xyz[0] == pytest.approx(FOOT_AT_PLATE * ROOT_LINK_LENGTH, abs=1e-9)
    assert xyz[0] == pytest.approx(0.04, abs=1e-9)


def test_flies_the_foot_at_plate_robot_with_table_vii(run):
    """MuJoCo's rotor sites put the foot rotors ~6 cm under the ceiling while perched (the
    shipped far-tip robot: 0.42 m), the arm rotors far below; the onboard perching QP holds
    Table VII's numbers with eq. (38)'s feedback gain at 0.25, and Spinal's roll/pitch
    integration is held while the root link turns, the contact confirmed over 0.05 s. Bugs
    caught: the variant flying the default robot (``robot`` not passed to the stack), the
    hanging scenario's eps_z = 8 N left in, the feedback gain, the integration hold or the
    contact hold not reaching the onboard node."""
    res, _, p, _ = run
    w = fp.thrust_windows(p, res.facts["t_perch"])
    foot = p["distance"][w["settled"]][:, list(fp.FOOT_ROTORS)]
    assert foot.size and np.all(np.abs(foot - 0.06) < 0.01), foot.min()
    assert np.all(p["distance"][w["settled"]][:, 2:] > 0.3)
    params = res.stack.onboard.control.perch.params()
    assert params["epsilon_z"] == 1.0
    assert (params["mu_x"], params["mu_y"], params["mu_z"]) == (0.9, 0.9, 0.5)
    assert (params["half_size_x"], params["half_size_y"]) == (0.04, 0.07)
    assert params["perch_rotors"] == [1.0, 1.0, 0.0, 0.0]
    assert params["feedback_gain"] == 0.25
    assert res.stack.onboard.config.rp_integration_hold_rate == 0.02
    assert res.stack.onboard.config.flight.contact_hold_s == 0.05
    assert res.stack.onboard.counts["rp_integration_held"] >= 1
    assert res.facts["robot"] == fp.ROBOT
    # the servo goal smoothing reaches MuJoCo: every joint servo a 0.05 s first-order filter
    m = res.stack.plant.model
    servos = [m.actuator(f"{j}_servo") for j in res.stack.plant.joint_names]
    assert all(int(a.dyntype[0]) == int(mujoco.mjtDyn.mjDYN_FILTEREXACT) for a in servos)
    assert all(a.dynprm[0] == 0.05 for a in servos)
    assert fp.SERVO.kp == 150.0 and fp.SERVO.kv == 5.0  # the stack's servo otherwise


def test_ceiling_gain_is_the_plants_model_at_the_site_distance(run):
    """The gain that turns applied thrust into the rotor's own thrust, recomputed from the
    Sanchez-Cuevas form written out here (k1 = 4.7, k2 = 0.8 R, cap 1.5, docs/plant.md) at the
    probe's MuJoCo distances; and the probe's applied thrusts are MuJoCo's (equal to the
    ground-truth record at the same instants). Bugs caught: the ratio taken as 1 (applied
    thrust reported as the rotor's own), a gain from another rotor's distance."""
    _, _, p, a = run
    r = ROTOR_DIAMETER / 2
    z = np.where(np.isfinite(p["distance"]), np.maximum(p["distance"], 0.0), np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        raw = 1.0 / (1.0 - (r / (z + 0.8 * r)) ** 2 / 4.7)
    expected = np.where(np.isfinite(z), np.minimum(raw, 1.5), 1.0)
    np.testing.assert_allclose(p["gain"], expected, rtol=1e-12)
    # applied thrusts: the truth record at the same simulated times
    k = np.clip(np.searchsorted(a["t"], p["t"] - 1e-6), 0, len(a["t"]) - 1)
    same = np.abs(a["t"][k] - p["t"]) < 1e-6
    assert same.sum() > 0.9 * len(p["t"])
    np.testing.assert_allclose(p["applied"][same], a["thrust"][k[same]], rtol=1e-12)


def test_thrust_rows_recomputed_from_the_probe(run):
    """The foot-thrust rows from the raw records: the flight level is the mean own thrust of
    rotors 1-2 over the last second before the approach (the phase after "reconfigure"
    starts), settled = 0.5 s after the switch to the start of the arm motion. Bugs caught: the
    flight window taken during the climb (straight arm, other thrust split), the peak row
    over both foot rotors' sum, the ratios inverted."""
    res, rows, p, _ = run
    t, phase = p["t"], p["phase"]
    own = (p["applied"] / p["gain"])[:, :2].mean(axis=1)
    first_approach = t[np.flatnonzero(phase == "approach")[0]]
    flight_sel = (t > first_approach - 1.0 - 1e-9) & (t < first_approach) & (phase != "approach")
    flight = own[flight_sel].mean()
    assert 9.0 < flight < 13.0  # hover share of 3.7 kg on the foot pair
    tp = res.facts["t_perch"]
    motion_start = t[np.flatnonzero(phase == "motion")[0]]
    settled = own[(t >= tp + 0.5) & (t < motion_start)].mean()
    hold = own[phase == "hold"].mean()
    peak = own[(t >= tp) & (t < tp + 1.0)].max()
    assert rows["foot rotor thrust settled after contact / flight"].ours == pytest.approx(
        settled / flight, rel=2e-3
    )
    assert rows["foot rotor thrust in the hold after the arm motion / flight"].ours == (
        pytest.approx(hold / flight, rel=2e-3)
    )
    assert rows["foot rotor thrust peak at the transition / flight"].ours == pytest.approx(
        peak / flight, rel=2e-3
    )
    assert rows["foot rotor thrust peak at the transition / flight"].paper == fp.PAPER_PEAK_RATIO
    assert rows["foot rotor thrust settled after contact / flight"].paper == 1.0
    assert rows["foot rotor thrust settled after contact / flight"].tol == fp.THRUST_RATIO_TOL


def test_contact_rows_recomputed_from_truth(run):
    """Contact kept, slip, min F_z, friction usage and the ZMP-on-edge time, per sample from
    MuJoCo's foot contact record. Bugs caught: H_x and H_y swapped (plate 0.10 x 0.15), the
    window starting at first contact instead of 0.5 s after the switch, mu_z used for the
    lateral cone."""
    res, rows, _, a = run
    tp = res.facts["t_perch"]
    assert tp is not None, "never perched"
    sel = a["t"] >= tp + 0.5
    f, m, zmp, slip = a["force"][sel], a["torque"][sel], a["zmp"][sel], a["slip"][sel]
    assert rows["foot contact kept while perched"].ours == pytest.approx(a["contact"][sel].mean())
    drift = max(math.dist(s, slip[0]) for s in slip) * 1e3
    assert rows["foot slip while perched"].ours == pytest.approx(drift, rel=1e-9)
    assert rows["min normal force while perched"].ours == pytest.approx(f[:, 2].min(), abs=1e-12)
    assert rows["min normal force while perched"].paper == 1.0  # Table VII's eps_z
    on = f[:, 2] > 0
    cone = np.max(np.abs(f[on, :2]) / (0.9 * f[on, 2:3]))
    assert rows["max friction-cone usage |F_t|/(mu F_z)"].ours == pytest.approx(cone, rel=1e-9)
    yaw = np.max(np.abs(m[on, 2]) / (0.5 * f[on, 2]))
    assert rows["max yaw-friction usage |M_z|/(mu_z F_z)"].ours == pytest.approx(yaw, rel=1e-9)
    late = a["t"][sel] >= tp + perching.SETTLE_S
    zl = zmp[late]
    off = (0.05 - np.abs(zl[:, 0]) > 1e-3) & (0.075 - np.abs(zl[:, 1]) > 1e-3)  # nan: on edge
    edge_row = rows[f"time with the ZMP on the plate edge (< {perching.EDGE_MM:g} mm)"]
    assert edge_row.ours == pytest.approx(1.0 - off.mean(), abs=1e-3)


def test_perches_and_finishes_the_arm_motion(run):
    """Outcomes that hold on this geometry: contact reached, every perching QP tick solved
    or rate-limited, the arm at its goal. Bug caught: the variant's script stopping before
    the motion (the hold row would then be empty: nan)."""
    res, rows, _, _ = run
    assert rows["perched (foot contact reached)"].ours == 1.0
    assert res.facts["final_phase"] == "hold"
    assert rows["perching QP solved ticks"].ours >= 0.99
    assert rows["joint goal reached after the motion"].ours < 5.0
    assert math.isfinite(rows["foot rotor thrust in the hold after the arm motion / flight"].ours)


def test_edge_split_recomputed_from_truth(run):
    """The ZMP-on-edge time split by the script's phase at each truth sample: the arm motion
    and the rest (settle, hold), both from 1.5 s after the switch. Bugs caught: the split
    taken from the probe's ticks instead of the truth samples, the settle's first 1.5 s (the
    contact transient) counted as rest, the two windows swapped."""
    res, rows, p, a = run
    tp = res.facts["t_perch"]
    t, zmp = a["t"], a["zmp"]
    motion_t = p["t"][p["phase"] == "motion"]
    start, end = motion_t.min(), motion_t.max()
    off = (0.05 - np.abs(zmp[:, 0]) > 1e-3) & (0.075 - np.abs(zmp[:, 1]) > 1e-3)
    late = t >= tp + 1.5
    during = late & (t >= start) & (t < end + 0.01)
    rest = late & ~during
    got_motion = rows["time with the ZMP on the plate edge during the arm motion"].ours
    got_rest = rows["time with the ZMP on the plate edge at rest (settled and hold)"].ours
    assert got_motion == pytest.approx(1.0 - off[during].mean(), abs=5e-3)
    assert got_rest == pytest.approx(1.0 - off[rest].mean(), abs=5e-3)


def test_measured_state_of_the_perch(run):
    """docs/scenarios.md's seed-0 figures with margins: the foot thrust settled and in the hold
    within 7 % of flight (1.04 / 1.04; with the fold's integral kept 1.08-1.11), the normal
    force above Table VII's eps_z with room (1.33 N; 1.11 N with kappa = 0.5, 0.96 N with
    kappa = 1), the plate off its edge at rest (0 %) and during the arm motion (0.5 %; 28 %
    with the servo goals stepping unsmoothed, 2.9 % with a 0.03 s goal filter), contact
    kept, no slip. Bugs caught: the integration hold or the feedback gain lost (thrust, F_z,
    edge time), the contact switch on the first reading (edge time at rest), the settle cut
    back to 1.5 s (the settled thrust then still in the transition), the servo goal
    smoothing lost or shortened (edge time during the motion)."""
    _, rows, _, _ = run
    settled = rows["foot rotor thrust settled after contact / flight"].ours
    hold = rows["foot rotor thrust in the hold after the arm motion / flight"].ours
    assert 0.97 < settled < 1.07 and 0.97 < hold < 1.07, (settled, hold)
    assert rows["foot rotor thrust settled after contact / flight"].passed
    assert rows["min normal force while perched"].ours > 1.2
    assert rows["time with the ZMP on the plate edge at rest (settled and hold)"].ours < 0.02
    assert rows["time with the ZMP on the plate edge during the arm motion"].ours < 0.02
    assert rows[f"time with the ZMP on the plate edge (< {perching.EDGE_MM:g} mm)"].passed
    assert rows["foot contact kept while perched"].ours == 1.0
    assert rows["foot slip while perched"].ours < 0.1
