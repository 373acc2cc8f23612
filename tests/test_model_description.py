"""Robot descriptions: shipped files are the generator's output, Table IV masses, and each
kind of bad description fails with a message naming the file and the field."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from rdm import descriptions
from rdm.model import DescriptionError, Robot, shipped_robot_files
from rdm.protocol import leptrino as lp


@pytest.mark.parametrize(
    "desc", descriptions.shipped_descriptions(), ids=lambda d: d.name
)  # rdm, rcm, rdm_foot10 (the foot unit at the plate: perching)
def test_shipped_files_equal_generator_output(desc: descriptions.Description) -> None:
    with shipped_robot_files(desc.name) as (urdf, toml):
        assert urdf.read_text() == desc.urdf, "run `python -m rdm.descriptions`"
        assert toml.read_text() == desc.toml, "run `python -m rdm.descriptions`"


@pytest.mark.parametrize("factory", [Robot.default, Robot.rcm])
def test_table_iv_total_mass_and_joint_order(factory) -> None:
    robot = factory()
    assert robot.mass == pytest.approx(3.35 + 0.35, abs=1e-12)  # links + foot module
    assert robot.joint_names == [
        "q1", "q2", "q3", "q4", "q5", "q6", "alpha1", "beta1", "alpha2", "beta2"
    ]  # fmt: skip
    assert robot.n_rotors == 4
    assert [r["spin"] for r in robot.rotors] == [1, -1, 1, -1]  # sigma_i = (-1)^(i+1)
    limits = robot.joint_limits
    assert limits[:6, 1] == pytest.approx([1.5707963267949] * 6, abs=1e-9)
    assert limits[6:, 1] == pytest.approx([3.14159265358979] * 4, abs=1e-9)
    assert list(robot.stall_torques) == [3.4] * 7 + [1.5, 3.4, 1.5]
    assert robot.plate_size == (0.10, 0.15)
    assert robot.sensors["foot_wrench"]["force_range"] == [150.0, 150.0, 300.0]
    assert robot.sensors["end_effector_wrench"]["torque_range"] == [1.0, 1.0, 1.0]


def test_rcm_puts_all_rotors_on_the_root_link() -> None:
    units = Robot.rcm().vectoring_units
    assert [u["parent_link"] for u in units] == ["root_link", "root_link"]
    assert [u["parent_link"] for u in Robot.default().vectoring_units] == [
        "root_link", "middle_link"
    ]  # fmt: skip


def test_arm_unit_variants_move_the_arm_rotors_along_the_middle_link() -> None:
    xs = []
    for position in (0.0, 0.5, 1.0):
        robot = Robot.variant("rdm", position)
        out = robot.evaluate([0.0] * robot.n_q)
        xs.append(out["rotor_positions"][2, 0])
        assert robot.mass == pytest.approx(3.70, abs=1e-12)
    assert xs == pytest.approx([0.40, 0.60, 0.80], abs=1e-12)


def _texts() -> tuple[str, str]:
    with shipped_robot_files("rdm") as (urdf, toml):
        return urdf.read_text(), toml.read_text()


def _load(urdf: str, toml: str) -> None:
    Robot.from_strs(urdf, toml, "bad.urdf", "bad.toml")


def test_missing_joint_names_the_joint_and_field() -> None:
    urdf, toml = _texts()
    # Drop the q3 joint; its child becomes a second root, so also re-parent it via fixed.
    urdf = urdf.replace('<joint name="q3" type="revolute">', '<joint name="q3_gone" type="fixed">')
    with pytest.raises(DescriptionError, match=r"bad\.toml: joint_order\[2\]: joint 'q3'"):
        _load(urdf, toml)


def test_negative_mass_names_the_link() -> None:
    urdf, toml = _texts()
    urdf = urdf.replace('<mass value="0.19"/>', '<mass value="-0.19"/>')
    with pytest.raises(
        DescriptionError, match=r"bad\.urdf: link 'end_link' <inertial>/<mass value>: negative mass"
    ):
        _load(urdf, toml)


def test_nan_names_the_field() -> None:
    urdf, toml = _texts()
    urdf = re.sub(
        r'(<joint name="q4" type="revolute">.*?<origin xyz=")[^"]*', r"\1nan 0 0", urdf, flags=re.S
    )
    with pytest.raises(
        DescriptionError, match=r"bad\.urdf: joint 'q4'/<origin xyz>: 'nan' is not finite"
    ):
        _load(urdf, toml)
    urdf, toml = _texts()
    toml = toml.replace("drag_to_thrust = 0.016", "drag_to_thrust = nan", 1)
    with pytest.raises(DescriptionError, match=r"bad\.toml: rotors\[0\] \('rotor1'\)"):
        _load(urdf, toml)


def test_unknown_rotor_parent_names_the_rotor() -> None:
    urdf, toml = _texts()
    toml = toml.replace('parent = "arm_unit_pitch"', 'parent = "arm_unit_pich"', 1)
    with pytest.raises(
        DescriptionError,
        match=r"bad\.toml: rotors\[2\] \('rotor3'\)\.parent: unknown link 'arm_unit_pich'",
    ):
        _load(urdf, toml)


def test_malformed_xml_and_toml_and_missing_files() -> None:
    urdf, toml = _texts()
    with pytest.raises(DescriptionError, match=r"bad\.urdf: malformed XML"):
        _load(urdf[:-20], toml)
    with pytest.raises(DescriptionError, match=r"(?s)bad\.toml: .*unknown field `joint_ordre`"):
        _load(urdf, toml.replace("joint_order", "joint_ordre"))
    no_frames = toml.replace('end_effector = "end_effector"\n', "", 1)
    with pytest.raises(DescriptionError, match=r"bad\.toml: frames\.end_effector: required"):
        _load(urdf, no_frames)
    with pytest.raises(DescriptionError, match=r"nowhere\.urdf"):
        Robot.from_files(Path("nowhere.urdf"), Path("nowhere.toml"))


def test_a_robot_without_mass_is_refused() -> None:
    urdf, toml = _texts()
    massless = re.sub(r'<mass value="[^"]*"/>', '<mass value="0"/>', urdf)
    assert massless.count('<mass value="0"/>') == urdf.count("<mass value=")
    with pytest.raises(
        DescriptionError,
        match=r"bad\.urdf: <robot> .*<mass value>: total mass 0 kg: .*must sum to more than 0",
    ):
        _load(massless, toml)


def test_a_vectoring_unit_with_one_joint_for_roll_and_pitch_is_refused() -> None:
    urdf, toml = _texts()
    same = toml.replace('pitch_joint = "beta2"', 'pitch_joint = "alpha2"', 1)
    assert same != toml
    with pytest.raises(
        DescriptionError,
        match=r"bad\.toml: vectoring_units\[1\] \('arm_unit'\)\.pitch_joint: joint 'alpha2' is "
        r"also the roll_joint: the two must differ",
    ):
        _load(urdf, same)


def test_an_unknown_sensor_model_is_refused() -> None:
    urdf, toml = _texts()
    unknown = toml.replace('model = "CFS018CA201"', 'model = "CFS999"', 1)
    assert unknown != toml
    with pytest.raises(
        DescriptionError,
        match=r"bad\.toml: sensors\.end_effector_wrench\.model: unknown sensor model 'CFS999' "
        r"\(known: CFS034CA301U, ",
    ):
        _load(urdf, unknown)


def test_the_known_sensor_models_include_every_leptrino_model() -> None:
    """Every model the Leptrino decoder knows loads (a description naming it is accepted)."""
    urdf, toml = _texts()
    for model in lp.MODELS:
        Robot.from_strs(urdf, toml.replace('model = "CFS034CA301U"', f'model = "{model}"', 1),
                        "ok.urdf", "ok.toml")  # fmt: skip
