"""The onboard node's configuration files (rdm.nodes.onboard_config_file, ``rdm config``,
``rdm onboard --config``): the shipped example is the defaults, a file changes what it names
and nothing else, every broken file is one line naming the file and the field, exit 2."""

from __future__ import annotations

import dataclasses
import json
import math
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from spinal_peer import drive_spinal, read_line

from rdm.cli import main
from rdm.nodes.onboard_config import OnboardConfig, PwmInfoParams, ServoMap
from rdm.nodes.onboard_config_file import (
    EXAMPLE_FILE,
    ConfigFileError,
    OnboardPorts,
    load_onboard_file,
)
from rdm.nodes.onboard_flight import FlightLimits

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

pytestmark = pytest.mark.timeout(120)


def write(tmp_path: Path, text: str, name: str = "robot.toml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


# -- the shipped example ----------------------------------------------------------------------


def test_example_resolves_to_the_defaults() -> None:
    """Field by field: a default changed in OnboardConfig (or a typo in the file) fails and
    names the field. The one deliberate difference: the LQI weights the robot flies
    (tests/test_onboard_roll_damping.py checks what they do)."""
    loaded = load_onboard_file(EXAMPLE_FILE)
    default = OnboardConfig(
        lqi_q_weights=(20.0, 30.0, 30.0, 1.0, 600.0, 80.0, 100.0, 50.0, 20.0, 0.15, 1.0, 0.5)
    )
    for f in dataclasses.fields(OnboardConfig):
        assert getattr(loaded.config, f.name) == getattr(default, f.name), f.name
    assert loaded.ports == OnboardPorts()


def _fields_with_values(cls: type, prefix: str = "") -> set[str]:
    """Dotted names of every field whose default is not None (TOML cannot write None)."""
    out = set()
    default = cls()
    for f in dataclasses.fields(cls):
        value = getattr(default, f.name)
        if value is None:
            continue
        if dataclasses.is_dataclass(value):
            out |= _fields_with_values(type(value), f"{prefix}{f.name}.")
        else:
            out.add(prefix + f.name)
    return out


def _keys(table: dict, prefix: str = "") -> set[str]:
    out = set()
    for k, v in table.items():
        if isinstance(v, dict) and k not in ("position_gains", "perch_params", "gain_profiles"):
            out |= _keys(v, f"{prefix}{k}.")
        else:
            out.add(prefix + k)
    return out


def test_example_spells_out_every_field() -> None:
    """The example documents every setting: a field added to OnboardConfig (or one of its
    tables) without a line in rdm.toml fails here (read with tomllib, not our loader)."""
    document = tomllib.loads(EXAMPLE_FILE.read_text())
    missing = _fields_with_values(OnboardConfig) - _keys(document)
    assert not missing, f"add {sorted(missing)} to {EXAMPLE_FILE.name}"


def test_config_check_prints_the_resolved_configuration(capsys) -> None:
    """JSON of every field; the servo map resolved from the robot's CAN wiring (Neuron
    slave order: the default wiring puts joint 0 at servo index 2, docs/canbus.md)."""
    assert main(["config", "check", str(EXAMPLE_FILE)]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["robot"] == "rdm" and out["ports"]["uart"] is None
    cfg = out["config"]
    assert cfg["rate_hz"] == 40.0 and cfg["pwm_info"]["motor_info"][0][0] == 25.2
    assert sorted(cfg["servo_map"]["servo_index"]) == list(range(10))
    assert set(cfg) == {f.name for f in dataclasses.fields(OnboardConfig)}


def test_config_example_prints_the_shipped_file(capsys) -> None:
    assert main(["config", "example"]) == 0
    assert capsys.readouterr().out == EXAMPLE_FILE.read_text()


# -- a file changes what it names -------------------------------------------------------------

THREE_CHANGES = """
rate_hz = 50
[flight]
takeoff_height = 0.8
[pwm_info]
motor_info = [[16.8, 12.0, 10.0, -5.0, 0.1, 0.0, 0.0], [25.2, 20.0, 12.0, -6.0, 0.08, 0.0, 0.0]]
"""


def test_three_values_change_exactly_three_fields(tmp_path) -> None:
    loaded = load_onboard_file(write(tmp_path, THREE_CHANGES))
    expected = dataclasses.replace(
        OnboardConfig(),
        rate_hz=50.0,
        flight=dataclasses.replace(FlightLimits(), takeoff_height=0.8),
        pwm_info=dataclasses.replace(
            PwmInfoParams(),
            motor_info=(
                (16.8, 12.0, 10.0, -5.0, 0.1, 0.0, 0.0),
                (25.2, 20.0, 12.0, -6.0, 0.08, 0.0, 0.0),
            ),
        ),
    )
    for f in dataclasses.fields(OnboardConfig):
        assert getattr(loaded.config, f.name) == getattr(expected, f.name), f.name
    assert isinstance(loaded.config.rate_hz, float)  # TOML 50 is the float 50.0


def test_tables_gains_profiles_servo_map_and_ports(tmp_path) -> None:
    text = """
[position_gains]
x_pid = [1.5, 0.1, 1.0]
[gain_profiles.fold]
x_pid = [2.0, 0.0, 2.0]
k_roll = 0.5
[perch_params]
mu_z = 0.4
solver = "clarabel"
[servo_map]
servo_index = [9, 8, 7, 6, 5, 4, 3, 2, 1, 0]
angle_sign = [1, -1, 1, -1, 1, -1, 1, -1, 1, -1]
[ports]
uart = "serial:/dev/flight_controller@921600"
foot_sensor = "none"
control = "udp:0.0.0.0:7301"
key = "keys/robot.key"
"""
    loaded = load_onboard_file(write(tmp_path, text))
    c = loaded.config
    assert c.position_gains == {"x_pid": (1.5, 0.1, 1.0)}
    assert c.gain_profiles == {"fold": {"x_pid": (2.0, 0.0, 2.0), "k_roll": 0.5}}
    assert c.perch_params == {"mu_z": 0.4, "solver": "clarabel"}
    # servo_index given with the signs: zeros and scales are the Dynamixel X ones
    # (4096 ticks per turn around 2048)
    assert c.servo_map == ServoMap(
        servo_index=tuple(range(9, -1, -1)),
        zero_point=(2048,) * 10,
        angle_scale=(2 * math.pi / 4096,) * 10,
        angle_sign=(1, -1) * 5,
    )
    assert loaded.ports == OnboardPorts(
        uart="serial:/dev/flight_controller@921600",
        foot_sensor="none",
        control="udp:0.0.0.0:7301",
        key=str(tmp_path / "keys" / "robot.key"),  # relative to the file's folder
    )


# -- broken files -----------------------------------------------------------------------------

BROKEN = [
    # (file text, the field the message names, a word of the rule)
    ("rate_hzz = 40.0\n", "rate_hzz", "unknown key"),
    ("[flight]\ntakeof_height = 1.0\n", "flight.takeof_height", "unknown key"),
    ("[ports]\nuart_port = 'pty'\n", "ports.uart_port", "unknown key"),
    ('rate_hz = "fast"\n', "rate_hz", "expected a number"),
    ("lqi_every = 1.5\n", "lqi_every", "expected an integer"),
    ("vectoring = 1\n", "vectoring", "expected a boolean"),
    ("[flight]\nmax_velocity = 0.5\n", "flight.max_velocity", "expected an array"),
    ("rate_hz = -40.0\n", "rate_hz", "> 0"),
    ("rate_hz = nan\n", "rate_hz", "finite"),
    ("[flight]\nmax_tilt_cmd = 1.2\n", "flight.max_tilt_cmd", "fail-safe"),
    ("[monitors]\ncell_low = 2.0\n", "monitors.cell_low", "cell_plausible"),
    ("[flight]\nmax_velocity = [0.5, 0.5, 0.3]\n", "flight.max_velocity", "needs 4 values"),
    (
        "[pwm_info]\nmotor_info = [[25.2, 20.0, 12.36, -6.63, 0.08, 0.0]]\n",
        "pwm_info.motor_info[0]",
        "6 columns",
    ),
    ("[pwm_info]\nmode = 3\n", "pwm_info.mode", "SQRT"),
    ("uav_model = 3\n", "uav_model", "HYDRUS"),
    ("[gain_profiles.fold]\nx_pidd = [1.0, 0.0, 1.0]\n", "gain_profiles.fold.x_pidd", "x_pidd"),
    ("[position_gains]\nx_pid = [1.0, 0.0]\n", "position_gains.x_pid", "length 3"),
    ('[gain_profiles."fold gains"]\nk_roll = 1.0\n', "gain_profiles.fold gains", "1-64 of"),
    ("[perch_params]\nmu_zz = 0.5\n", "perch_params.mu_zz", "unknown perch parameter"),
    ("lqi_r_weights = [1.0, 2.0]\n", "lqi_r_weights", "length 4"),
    ("[servo_map]\nservo_index = [0, 0, 1, 2, 3, 4, 5, 6, 7, 8]\n", "servo_map", "duplicates"),
    ("[ports]\nuart = 'ttyUSB0'\n", "ports.uart", "unrecognised serial spec"),
    ("[ports]\ncontrol = 'udp:robot'\n", "ports.control", "udp:HOST:PORT"),
    ("rate_hz = = 40\n", "line 1", "not valid TOML"),
]


@pytest.mark.parametrize(("text", "field", "rule"), BROKEN)
def test_broken_file_names_file_field_and_rule(tmp_path, capsys, text, field, rule) -> None:
    path = write(tmp_path, text)
    with pytest.raises(ConfigFileError) as exc:
        load_onboard_file(path)
    assert field in str(exc.value) and rule in str(exc.value)
    assert main(["config", "check", str(path)]) == 2
    captured = capsys.readouterr()
    (line,) = captured.err.splitlines()
    assert line.startswith(f"rdm config: {path}: ")
    assert field in line and rule in line
    assert captured.out == ""


@pytest.mark.parametrize(
    ("text", "field", "rule"),
    [
        ("motor_num = 6\n", "motor_num", "4 rotors"),
        ("[servo_map]\nservo_index = [0, 1, 2]\n", "servo_map.servo_index", "10 joints"),
        ("initial_q = [0.0, 0.1]\n", "initial_q", "10 finite values"),
        ('imu_link = "wing"\n', "imu_link", "not a frame"),
    ],
)
def test_file_that_does_not_fit_the_robot(tmp_path, capsys, text, field, rule) -> None:
    """Checks that need the robot (``rdm config check --robot``): the file loads, the
    resolution for the RDM refuses it."""
    path = write(tmp_path, text)
    load_onboard_file(path)  # fine on its own
    assert main(["config", "check", str(path), "--robot", "rdm"]) == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert line.startswith(f"rdm config: {path}: {field}: ") and rule in line


def test_missing_file_names_it(tmp_path, capsys) -> None:
    path = tmp_path / "nothing.toml"
    assert main(["config", "check", str(path)]) == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert line.startswith(f"rdm config: {path}: ") and "No such file" in line


# -- rdm onboard --config ---------------------------------------------------------------------


def _onboard(args: list[str], cwd: Path) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "rdm.cli", "onboard", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=cwd,
    )


def test_onboard_refuses_a_broken_file_before_opening_ports(tmp_path) -> None:
    path = write(tmp_path, "[ports]\nuart = 'pty'\n[flight]\nmax_jerk = [2.0, 2.0]\n")
    proc = _onboard(["--config", str(path)], tmp_path)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 2
    assert err.strip() == (f"rdm onboard: {path}: flight.max_jerk: needs 4 values, got 2")
    assert "pty" not in out  # no port was opened


def test_command_line_overrides_the_file(tmp_path) -> None:
    """The file's rate and port run the node; ``--rate`` given on the command line wins."""
    path = write(tmp_path, "rate_hz = 50.0\n[ports]\nuart = 'loop://'\n")
    for extra, rate in (([], "50.0"), (["--rate", "20"], "20.0")):
        proc = _onboard(["--config", str(path), "--duration", "0.3", *extra], tmp_path)
        out, err = proc.communicate(timeout=60)
        assert proc.returncode == 0, err
        assert f"rdm onboard: ready robot=rdm rate={rate} Hz" in out


def test_onboard_sends_the_files_motor_info(tmp_path) -> None:
    """``rdm onboard --config FILE`` alone: the file's port (a pty), its ``pwm_info`` and
    ``uav_info`` reach Spinal on the wire (as float32)."""
    path = write(
        tmp_path,
        """
[pwm_info]
min_pwm = 0.55
force_landing_thrust = 5.0
motor_info = [[16.8, 12.0, 10.0, -5.0, 0.1, 0.0, 0.0]]
[ports]
uart = "pty"
foot_sensor = "none"
""",
    )
    proc = _onboard(["--config", str(path), "--arm", "--duration", "60"], tmp_path)
    try:
        uart_path = read_line(proc, "rdm onboard: uart pty").split()[-1]
        read_line(proc, "rdm onboard: ready")
        _spinal, got = drive_spinal(uart_path, 50.0, done=lambda got: "motor_info" in got)
        proc.send_signal(signal.SIGTERM)
        _out, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 0, err
    pwm = got["motor_info"][0]
    f32 = np.float32
    assert (pwm.min_pwm, pwm.max_pwm, pwm.force_landing_thrust) == (f32(0.55), f32(0.9375), 5.0)
    (unit,) = pwm.motor_info
    assert (unit.voltage, unit.max_thrust) == (f32(16.8), 12.0)
    assert list(unit.polynominal) == [10.0, -5.0, f32(0.1), 0.0, 0.0]
