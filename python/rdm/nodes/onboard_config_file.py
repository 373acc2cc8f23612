"""The onboard node's configuration as a TOML file (``rdm onboard --config FILE``,
``rdm config check FILE``; docs/onboard.md "Configuration files").

The file's keys are the fields of :class:`rdm.nodes.onboard_config.OnboardConfig`, with the
same names and units; its nested dataclasses are tables (``[pwm_info]``, ``[servo_map]``,
``[flight]``, ``[monitors]``), the keyword overrides are tables of numbers and arrays
(``[position_gains]``, ``[perch_params]``, ``[gain_profiles.NAME]``), and ``[ports]`` names the
node's ports (``uart``, ``foot_sensor``, ``control``, ``key``). A key the file leaves out keeps
its default; the shipped example ``rdm/data/onboard/rdm.toml`` spells out every default and
sets ``lqi_q_weights`` to the roll weights the robot flies (``lqi.ROLL_DAMPED_Q``).

Every value is checked where it is read: unknown keys, TOML types against the field's type
hint, finite numbers, array lengths, then the dataclasses' own ``__post_init__`` rules, the
position gains by :class:`rdm.control.position.PositionController`, the perching parameters by
:class:`rdm.control.perch.PerchController`, the LQI weights by
:class:`rdm.control.lqi.LqiSynthesizer`, ``pwm_info`` by :class:`rdm.pwm.PwmConverter`: each
refusal is a :class:`ConfigFileError` naming the file, the dotted field and the rule.
:func:`resolve_for_robot` adds the checks that need the robot (joint count of the servo map
and ``initial_q``, ``imu_link``, the control pipeline built as the node builds it).

ASSUMPTION: a relative ``ports.key`` path is relative to the configuration file's folder (the
file and the key travel together), not to the working directory.
"""

from __future__ import annotations

import dataclasses
import json
import math
import re
import sys
import types
import typing
from dataclasses import dataclass
from pathlib import Path
from typing import Any

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

from rdm.nodes.onboard_config import (
    DYNAMIXEL_RAD_PER_TICK,
    DYNAMIXEL_ZERO,
    OnboardConfig,
    ServoMap,
)

#: The shipped example: every field at its default (``rdm config example`` prints it).
EXAMPLE_FILE = Path(__file__).resolve().parent.parent / "data" / "onboard" / "rdm.toml"

#: Columns of one ``pwm_info.motor_info`` row (``spinal/MotorInfo``: voltage, max thrust and
#: the five coefficients of the thrust -> PWM curve).
MOTOR_INFO_COLUMNS = ("voltage", "max_thrust", "p0", "p1", "p2", "p3", "p4")

#: A gain profile may not take this name: ``set_gain_profile("default")`` is ``position_gains``.
DEFAULT_PROFILE = "default"


class ConfigFileError(ValueError):
    """A configuration file that cannot be used: ``file``, the dotted ``field`` (empty for
    the whole file) and the ``rule`` it breaks; ``str()`` is ``"FILE: FIELD: RULE"``."""

    def __init__(self, file: str | Path, field: str, rule: str) -> None:
        self.file, self.field, self.rule = str(file), field, rule
        super().__init__(f"{self.file}: {field}: {rule}" if field else f"{self.file}: {rule}")


@dataclass(frozen=True)
class OnboardPorts:
    """``[ports]``: the node's ports as ``rdm onboard`` takes them (None: not in the file)."""

    #: Spinal UART: ``serial:/dev/...[@baud]`` or ``pty``.
    uart: str | None = None
    #: Leptrino foot sensor: ``serial:/dev/...[@baud]``, ``pty`` or ``none``.
    foot_sensor: str | None = None
    #: The ground link: ``udp:HOST:PORT`` (``rdm ctl --to``).
    control: str | None = None
    #: The ground link's key file (relative paths: from the configuration file's folder).
    key: str | None = None


@dataclass(frozen=True)
class OnboardFile:
    """A loaded configuration file: its path, the node configuration and the ports."""

    path: Path
    config: OnboardConfig
    ports: OnboardPorts


_TOML_TYPE = {
    bool: "a boolean",
    int: "an integer",
    float: "a float",
    str: "a string",
    list: "an array",
    dict: "a table",
}


def _kind(raw: Any) -> str:
    return _TOML_TYPE.get(type(raw), f"a TOML {type(raw).__name__}")


def _join(where: str, key: str | int) -> str:
    if isinstance(key, int):
        return f"{where}[{key}]"
    return f"{where}.{key}" if where else key


class _Reader:
    """Converts one parsed TOML document; every refusal names ``file``."""

    def __init__(self, file: Path) -> None:
        self.file = file

    def fail(self, field: str, rule: str) -> ConfigFileError:
        return ConfigFileError(self.file, field, rule)

    # -- scalars and arrays ----------------------------------------------------------------
    def value(self, where: str, hint: Any, raw: Any) -> Any:
        """``raw`` converted to the type ``hint`` (the dataclass field's annotation)."""
        origin = typing.get_origin(hint)
        if origin in (typing.Union, types.UnionType):
            # X | None: the file cannot write None (TOML has no null); leaving it out keeps it
            (inner,) = (a for a in typing.get_args(hint) if a is not type(None))
            return self.value(where, inner, raw)
        if dataclasses.is_dataclass(hint):
            return self.table(where, hint, raw)
        if hint is bool:
            if not isinstance(raw, bool):
                raise self.fail(where, f"expected a boolean, got {_kind(raw)} {raw!r}")
            return raw
        if hint is int:
            if isinstance(raw, bool) or not isinstance(raw, int):
                raise self.fail(where, f"expected an integer, got {_kind(raw)} {raw!r}")
            return raw
        if hint is float:
            return self.number(where, raw)
        if hint is str:
            if not isinstance(raw, str):
                raise self.fail(where, f"expected a string, got {_kind(raw)} {raw!r}")
            return raw
        if origin is tuple:
            return self.array(where, typing.get_args(hint), raw)
        raise TypeError(f"{where}: no TOML form for the type {hint!r}")  # a field type to add

    def number(self, where: str, raw: Any) -> float:
        if isinstance(raw, bool) or not isinstance(raw, (int, float)):
            raise self.fail(where, f"expected a number, got {_kind(raw)} {raw!r}")
        if not math.isfinite(raw):
            raise self.fail(where, f"{raw!r} is not a finite number")
        return float(raw)

    def array(self, where: str, args: tuple[Any, ...], raw: Any) -> tuple[Any, ...]:
        if not isinstance(raw, list):
            raise self.fail(where, f"expected an array, got {_kind(raw)} {raw!r}")
        if len(args) == 2 and args[1] is Ellipsis:
            hints = (args[0],) * len(raw)
        else:
            hints = args
            if len(raw) != len(hints):
                raise self.fail(where, f"needs {len(hints)} values, got {len(raw)}")
        return tuple(
            self.value(_join(where, i), h, v)
            for i, (h, v) in enumerate(zip(hints, raw, strict=True))
        )

    def plain(self, where: str, raw: Any) -> Any:
        """A value of a keyword-override table: a boolean, integer, finite float, string, or
        an array of those (as a tuple); the consumer checks names and meanings."""
        if isinstance(raw, (bool, int, str)):
            return raw
        if isinstance(raw, float):
            return self.number(where, raw)
        if isinstance(raw, list):
            return tuple(self.plain(_join(where, i), v) for i, v in enumerate(raw))
        raise self.fail(where, f"expected a number, boolean, string or array, got {_kind(raw)}")

    # -- tables ----------------------------------------------------------------------------
    def known_keys(self, where: str, table: Any, known: typing.Iterable[str]) -> dict:
        if not isinstance(table, dict):
            raise self.fail(where, f"expected a table, got {_kind(table)} {table!r}")
        known = tuple(known)
        unknown = [k for k in table if k not in known]
        if unknown:
            names = ", ".join(_join(where, k) for k in unknown)
            if len(known) > 12:
                hint = "OnboardConfig's fields and [ports]; `rdm config example` lists them"
            else:
                hint = f"known: {', '.join(known)}"
            raise self.fail(names, f"unknown key ({hint})")
        return table

    def table(self, where: str, cls: type, table: Any) -> Any:
        """The dataclass ``cls`` from a TOML table: fields by their type hints, then the
        class's own checks (its ``__post_init__``)."""
        names = [f.name for f in dataclasses.fields(cls) if f.init]
        table = self.known_keys(where, table, names)
        hints = typing.get_type_hints(cls)
        kwargs: dict[str, Any] = {}
        for key, raw in table.items():
            field_where = _join(where, key)
            if cls is OnboardConfig and key in _OVERRIDE_TABLES:
                kwargs[key] = _OVERRIDE_TABLES[key](self, field_where, raw)
            else:
                kwargs[key] = self.value(field_where, hints[key], raw)
        if cls is ServoMap:
            kwargs = _servo_map_defaults(kwargs)
        return self.construct(where, cls, kwargs)

    def construct(self, where: str, cls: Any, kwargs: dict[str, Any]) -> Any:
        """``cls(**kwargs)``; its ValueError names the fields its message mentions (those
        the file sets first), else the table."""
        try:
            return cls(**kwargs)
        except ValueError as exc:
            raise self.fail(self.culprit(where, str(exc), kwargs, cls), str(exc)) from None

    def culprit(self, where: str, message: str, given: typing.Iterable[str], cls: Any) -> str:
        names = [f.name for f in dataclasses.fields(cls)] if dataclasses.is_dataclass(cls) else []
        names += [k for k in given if k not in names]
        said = [k for k in names if re.search(rf"\b{re.escape(k)}\b", message)]
        set_here = [k for k in said if k in given]
        chosen = set_here or said
        if not chosen:
            return where
        return ", ".join(_join(where, k) for k in chosen)

    # -- keyword overrides -------------------------------------------------------------------
    def gains(self, where: str, raw: Any) -> dict[str, Any]:
        """A table of position-controller keyword gains, checked by building the controller."""
        from rdm.control.position import PositionController

        table = self.known_keys(where, raw, raw if isinstance(raw, dict) else ())
        gains = {k: self.plain(_join(where, k), v) for k, v in table.items()}
        try:
            PositionController(**gains)
        except (TypeError, ValueError) as exc:  # an unknown name, a value of the wrong form
            field = self.culprit(where, str(exc), gains, None)
            if field == where:  # the message names no gain: the one refused on its own
                alone = [k for k in gains if not _builds(PositionController, {k: gains[k]})]
                field = ", ".join(_join(where, k) for k in alone) or where
            raise self.fail(field, str(exc)) from None
        return gains

    def profiles(self, where: str, raw: Any) -> dict[str, dict[str, Any]]:
        table = self.known_keys(where, raw, raw if isinstance(raw, dict) else ())
        if DEFAULT_PROFILE in table:
            raise self.fail(
                _join(where, DEFAULT_PROFILE),
                "the profile 'default' is [position_gains]; give it another name",
            )
        from rdm.ground.commands import _PROFILE as PROFILE_NAME  # what `rdm ctl gains` sends

        for name in table:
            if not PROFILE_NAME.fullmatch(name):
                raise self.fail(
                    _join(where, name), "a profile name is 1-64 of A-Z a-z 0-9 _ . - (rdm ctl)"
                )
        return {name: self.gains(_join(where, name), g) for name, g in table.items()}

    def perch(self, where: str, raw: Any) -> dict[str, Any]:
        """Perching-QP parameters (checked once the rate and cut-off are known)."""
        table = self.known_keys(where, raw, raw if isinstance(raw, dict) else ())
        return {k: self.plain(_join(where, k), v) for k, v in table.items()}


def _builds(cls: Any, kwargs: dict[str, Any]) -> bool:
    try:
        cls(**kwargs)
    except (TypeError, ValueError):
        return False
    return True


_OVERRIDE_TABLES: dict[str, typing.Callable[[_Reader, str, Any], Any]] = {
    "position_gains": _Reader.gains,
    "gain_profiles": _Reader.profiles,
    "perch_params": _Reader.perch,
}


def _servo_map_defaults(kwargs: dict[str, Any]) -> dict[str, Any]:
    """A ``[servo_map]`` that gives ``servo_index`` only: every servo a Dynamixel X
    (centre 2048, 4096 ticks per turn, sign +1), as :class:`ServoMap`'s defaults are."""
    n = len(kwargs.get("servo_index", ServoMap().servo_index))
    kwargs.setdefault("zero_point", (DYNAMIXEL_ZERO,) * n)
    kwargs.setdefault("angle_scale", (DYNAMIXEL_RAD_PER_TICK,) * n)
    kwargs.setdefault("angle_sign", (1,) * n)
    return kwargs


#: How the LQI core names the weights in its messages -> the configuration's fields.
_LQI_NAMES = (
    ("`q_weights", "`lqi_q_weights"),
    ("`r_weights", "`lqi_r_weights"),
    ("weights.q", "lqi_q_weights"),
    ("weights.r", "lqi_r_weights"),
)

#: ``spinal/UavInfo``'s model constants (firmware_protocol UavInfo.msg).
UAV_MODELS = {"DRONE": 0, "HYDRUS": 16, "HYDRUS_XI": 17, "DRAGON": 32}


def _check_consumers(reader: _Reader, config: OnboardConfig) -> None:
    """The checks of the parts the configuration feeds (robot-independent)."""
    import numpy as np

    from rdm.control.attitude import MAX_ROTORS
    from rdm.control.lqi import LqiSynthesizer
    from rdm.control.perch import PerchController
    from rdm.pwm import PwmConverter

    if config.uav_model not in UAV_MODELS.values():
        models = ", ".join(f"{k} {v}" for k, v in UAV_MODELS.items())
        raise reader.fail("uav_model", f"{config.uav_model} is not one of {models}")
    if not 1 <= config.motor_num <= MAX_ROTORS:
        raise reader.fail(
            "motor_num", f"{config.motor_num} is not in 1..{MAX_ROTORS} (the rotors the core holds)"
        )
    p = config.pwm_info
    for i, row in enumerate(p.motor_info):
        if len(row) != len(MOTOR_INFO_COLUMNS):
            raise reader.fail(
                f"pwm_info.motor_info[{i}]",
                f"{len(row)} columns; a row is {', '.join(MOTOR_INFO_COLUMNS)}",
            )
    checks: list[tuple[str, dict[str, Any], typing.Callable[[], Any]]] = [
        (
            "pwm_info",
            {f.name: 0 for f in dataclasses.fields(p)},
            lambda: PwmConverter(
                p.min_pwm,
                p.max_pwm,
                p.min_thrust,
                p.force_landing_thrust,
                p.mode,
                np.array(p.motor_info, dtype=float).reshape(-1, len(MOTOR_INFO_COLUMNS)),
            ),
        ),
        (
            "",
            {"lqi_q_weights": 0, "lqi_r_weights": 0},
            lambda: LqiSynthesizer(
                None if config.lqi_q_weights is None else np.array(config.lqi_q_weights),
                None if config.lqi_r_weights is None else np.array(config.lqi_r_weights),
                clamp_gain=True,
                rotors=config.motor_num,
            ),
        ),
        (
            "perch_params",
            config.perch_params,
            lambda: PerchController(config.rate_hz, config.perch_cutoff_hz, **config.perch_params),
        ),
    ]
    for where, given, build in checks:
        try:
            build()
        except ValueError as exc:
            rule = str(exc)
            # the LQI core names its inputs q_weights / r_weights
            rule_fields = rule
            for core_name, name in _LQI_NAMES:
                rule_fields = rule_fields.replace(core_name, name)
            field = reader.culprit(where, rule_fields, given, None)
            raise reader.fail(field or "lqi_q_weights, lqi_r_weights", rule) from None


def _read_toml(path: Path) -> dict[str, Any]:
    try:
        with open(path, "rb") as f:
            return tomllib.load(f)
    except OSError as exc:
        raise ConfigFileError(path, "", exc.strerror or str(exc)) from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigFileError(path, "", f"not valid TOML: {exc}") from None
    except UnicodeDecodeError as exc:
        raise ConfigFileError(path, "", f"not UTF-8 text: {exc}") from None


def parse_onboard(document: dict[str, Any], path: str | Path) -> OnboardFile:
    """An :class:`OnboardFile` from a parsed TOML ``document``; ``path`` names it in errors
    and is the folder a relative ``ports.key`` is taken from."""
    path = Path(path)
    reader = _Reader(path)
    document = dict(document)
    ports_raw = document.pop("ports", {})
    names = [f.name for f in dataclasses.fields(OnboardConfig) if f.init]
    reader.known_keys("", document, [*names, "ports"])
    config = reader.table("", OnboardConfig, document)
    _check_consumers(reader, config)
    ports = reader.table("ports", OnboardPorts, ports_raw)
    for name in ("uart", "foot_sensor", "control", "key"):
        if getattr(ports, name) == "":
            raise reader.fail(f"ports.{name}", "empty; leave the key out instead")
    _check_ports(reader, ports)
    if ports.key is not None and not Path(ports.key).is_absolute():
        ports = dataclasses.replace(ports, key=str(path.parent / ports.key))
    return OnboardFile(path=path, config=config, ports=ports)


def _check_ports(reader: _Reader, ports: OnboardPorts) -> None:
    """Port strings parse (nothing is opened)."""
    from rdm.ground.address import parse_udp
    from rdm.link.serial import parse_serial_spec

    for name in ("uart", "foot_sensor"):
        spec = getattr(ports, name)
        if spec is None or (name == "foot_sensor" and spec == "none"):
            continue
        try:
            parse_serial_spec(spec)
        except ValueError as exc:
            raise reader.fail(f"ports.{name}", str(exc)) from None
    if ports.control is not None:
        try:
            parse_udp(ports.control, "control")
        except ValueError as exc:
            raise reader.fail("ports.control", str(exc)) from None


def load_onboard_file(path: str | Path) -> OnboardFile:
    """Read and check a configuration file (module doc); :class:`ConfigFileError` if it
    cannot be used."""
    path = Path(path)
    return parse_onboard(_read_toml(path), path)


def resolve_for_robot(loaded: OnboardFile, robot: Any) -> OnboardConfig:
    """``loaded.config`` for ``robot`` as the node uses it: the servo map from the robot's
    CAN wiring when the file gives none, the joint counts checked, the control pipeline
    built once (its refusals name the file)."""
    from rdm.nodes.onboard import default_servo_map
    from rdm.nodes.onboard_control import ControlPipeline

    reader = _Reader(loaded.path)
    config = loaded.config
    n_q = robot.n_q
    if config.servo_map is None:
        config = dataclasses.replace(config, servo_map=default_servo_map(robot))
    elif config.servo_map.n_joints != n_q:
        raise reader.fail(
            "servo_map.servo_index",
            f"{config.servo_map.n_joints} servos; the robot has {n_q} joints",
        )
    if config.motor_num != robot.n_rotors:
        raise reader.fail("motor_num", f"{config.motor_num}; the robot has {robot.n_rotors} rotors")
    try:
        config.initial_joint_vector(n_q)
    except ValueError as exc:
        raise reader.fail("initial_q", str(exc)) from None
    try:
        ControlPipeline(robot, config)
    except ValueError as exc:
        field = reader.culprit("", str(exc), (), OnboardConfig)
        raise reader.fail(field, str(exc)) from None
    return config


def config_json(config: OnboardConfig) -> dict[str, Any]:
    """The configuration as JSON-ready values (tuples as lists, tables as objects)."""
    return json.loads(json.dumps(dataclasses.asdict(config), allow_nan=False))
