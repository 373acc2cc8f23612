"""`rdm model` and `rdm model --json` run, and the JSON agrees with the Python API."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from rdm.cli import main
from rdm.model import Robot, shipped_robot_files


def test_human_output_has_the_tables(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["model"]) == 0
    text = capsys.readouterr().out
    for needle in ("mass     3.7000 kg", "allocation matrix Q(q)", "aerial ZMP", "rho ="):
        assert needle in text


@pytest.mark.parametrize("robot_arg", ["rdm", "rcm"])
def test_json_agrees_with_the_python_api(
    robot_arg: str, capsys: pytest.CaptureFixture[str]
) -> None:
    q = [0.5, -0.5, 0.2, 0.8, 0.6, 0.0, 0.1, -0.2, 0.3, 0.4]  # Sec. VII-A final configuration
    assert main(["model", "--robot", robot_arg, "--json", "--q", ",".join(map(str, q))]) == 0
    report = json.loads(capsys.readouterr().out)
    out = Robot.shipped(robot_arg).evaluate(q)
    assert report["mass"] == out["mass"]
    np.testing.assert_array_equal(report["cog"], out["cog"])
    np.testing.assert_array_equal(report["allocation"], out["allocation"])
    np.testing.assert_array_equal(report["aerial_zmp"], out["aerial_zmp"])
    assert report["zmp_margin"] == out["zmp_margin"]
    assert report["rho"] == out["rho"]


def test_custom_files_and_degrees(capsys: pytest.CaptureFixture[str]) -> None:
    with shipped_robot_files("rdm") as (urdf, toml):
        assert main(["model", "--urdf", str(urdf), "--toml", str(toml), "--json",
                     "--degrees", "--q", "90,0,0,0,0,0,0,-90,90,-90"]) == 0  # fmt: skip
    report = json.loads(capsys.readouterr().out)
    assert report["q"][0] == pytest.approx(math.pi / 2)
    assert report["zmp_inside"] is True


def test_bad_q_is_a_clear_error(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["model", "--q", "1,2"]) == 2
    assert "--q: expected 10 values, got 2" in capsys.readouterr().err
