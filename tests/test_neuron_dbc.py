"""The Neuron codec against cantools + the DBC files (an independent bit-layout description)."""

from __future__ import annotations

from pathlib import Path

import cantools
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from rdm.protocol import neuron as nr

DBC_DIR = Path(__file__).resolve().parents[1] / "firmware_protocol" / "neuron"


@pytest.fixture(scope="module")
def dbs():
    return {
        "s2n": cantools.database.load_file(DBC_DIR / "neuron_spinal_to_neuron.dbc"),
        "n2s": cantools.database.load_file(DBC_DIR / "neuron_neuron_to_spinal.dbc"),
        "bus": cantools.database.load_file(DBC_DIR / "neuron.dbc"),
    }


def test_all_dbc_files_load_strictly_and_cover_the_id_space(dbs):
    # 2 PWM + enum request + 14 slaves x (2 servo words + config request + board config)
    assert len(dbs["s2n"].messages) == 3 + 14 * 4
    # 14 slaves x (3 IMU + 4 servo states + enum response + 4 configs)
    assert len(dbs["n2s"].messages) == 14 * 12
    assert len(dbs["bus"].messages) == 14 * 12 + 3
    ids = [m.frame_id for m in dbs["bus"].messages]
    assert len(ids) == len(set(ids))
    for m in dbs["bus"].messages:
        assert m.frame_id == (
            m.dbc.attributes["NeuronDevice"].value << 8
            | m.dbc.attributes["NeuronMessage"].value << 4
            | m.dbc.attributes["NeuronSlave"].value
        )


slaves = st.integers(1, 14)
u8, u16 = st.integers(0, 0xFF), st.integers(0, 0xFFFF)
i16, i32 = st.integers(-0x8000, 0x7FFF), st.integers(-(2**31), 2**31 - 1)
idx = st.integers(0, 3)
word15 = st.integers(-(2**14), 2**14 - 1)


@st.composite
def servo_words(draw, cls):
    n = draw(st.integers(1, 4))
    values = tuple(draw(st.lists(word15, min_size=n, max_size=n)))
    flags = tuple(draw(st.lists(st.booleans(), min_size=n, max_size=n)))
    return cls(draw(slaves), values, flags)


FRAMES = st.one_of(
    st.builds(nr.PwmFrame, st.integers(0, 1), st.tuples(*[st.integers(0, 1000)] * 6)),
    st.builds(nr.ImuFrame, slaves, st.sampled_from(list(nr.ImuMessage)), i16, i16, i16),
    servo_words(nr.ServoTargetAngles),
    servo_words(nr.ServoTargetCurrents),
    st.builds(
        nr.ServoState, slaves, idx, i16, u8, st.booleans(), st.booleans(), st.booleans(), i16, u8
    ),
    st.just(nr.EnumRequest()),
    st.builds(nr.EnumResponse, slaves),
    st.builds(nr.InitialConfigRequest, slaves),
    st.builds(nr.InitialConfig0, slaves, st.integers(0, 4), st.booleans(), st.booleans(), u16),
    st.builds(nr.InitialConfig1, slaves, idx, u8, u16, u16, u16),
    st.builds(nr.InitialConfig2, slaves, idx, i16, u16, u16, st.booleans(), st.booleans()),
    st.builds(nr.InitialConfig3, slaves, idx, u8, i16, i16, i16),
    st.builds(nr.SetSlaveId, slaves, slaves),
    st.builds(nr.SetImuSendFlag, slaves, st.booleans()),
    st.builds(nr.SetServoHomingOffset, slaves, idx, i32),
    st.builds(nr.SetServoPidGain, slaves, idx, u16, u16, u16),
    st.builds(nr.SetServoProfileVel, slaves, idx, u16),
    st.builds(nr.SetSendDataFlag, slaves, idx, st.booleans()),
    st.builds(nr.SetServoCurrentLimit, slaves, idx, u16),
    st.builds(nr.Reboot, slaves),
    st.builds(nr.SetDynamixelTtlRs485Mixed, slaves, st.booleans()),
    st.builds(nr.SetExternalEncoderFlag, slaves, idx, st.booleans()),
    st.builds(nr.SetResolutionRatio, slaves, idx, i16, i16),
    st.builds(nr.SetServoRoundOffset, slaves, idx, i32),
    st.builds(nr.SetServoPulleySkipThresh, slaves, u16),
)

_BOARD_SIGNALS = {
    "SetSlaveId": {"new_id": "NewSlaveId"},
    "SetImuSendFlag": {"flag": "ImuSendFlag"},
    "SetServoHomingOffset": {"index": "HomingOffsetIndex", "offset": "HomingOffset"},
    "SetServoPidGain": {
        "index": "PidGainIndex",
        "p_gain": "PGain",
        "i_gain": "IGain",
        "d_gain": "DGain",
    },
    "SetServoProfileVel": {"index": "ProfileVelIndex", "profile_velocity": "ProfileVelocity"},
    "SetSendDataFlag": {"index": "SendDataFlagIndex", "flag": "SendDataFlag"},
    "SetServoCurrentLimit": {"index": "CurrentLimitIndex", "current_limit": "CurrentLimit"},
    "Reboot": {},
    "SetDynamixelTtlRs485Mixed": {"flag": "TtlRs485Mixed"},
    "SetExternalEncoderFlag": {"index": "ExternalEncoderIndex", "flag": "ExternalEncoderFlag"},
    "SetResolutionRatio": {
        "index": "ResolutionIndex",
        "joint_resolution": "JointResolution",
        "servo_resolution": "ServoResolution",
    },
    "SetServoRoundOffset": {"index": "RoundOffsetIndex", "offset": "RoundOffset"},
    "SetServoPulleySkipThresh": {"thresh": "PulleySkipThresh"},
}


def camel(name: str) -> str:
    return "".join(part.capitalize() for part in name.split("_"))


def dbc_view(f: nr.NeuronFrame) -> tuple[str, str, dict[str, int]]:
    """(database, message name, raw signal values) the DBC should show for this frame."""
    s = getattr(f, "slave", None)
    if isinstance(f, nr.PwmFrame):
        first = 1 + 6 * f.frame_index
        return (
            "s2n",
            f"MotorPwmSlaves{first}To{first + 5}",
            {f"Pwm{first + k}": v for k, v in enumerate(f.values)},
        )
    if isinstance(f, nr.ImuFrame):
        kind = f.sensor.name.capitalize()
        return "n2s", f"Imu{kind}_S{s:02d}", {f"{kind}X": f.x, f"{kind}Y": f.y, f"{kind}Z": f.z}
    if isinstance(f, (nr.ServoTargetAngles, nr.ServoTargetCurrents)):
        a = isinstance(f, nr.ServoTargetAngles)
        value, flag = ("GoalPosition", "GoalAck") if a else ("GoalCurrent", "TorqueEnable")
        sigs = {}
        for i, (v, fl) in enumerate(zip(f.values, f.flags, strict=True)):
            sigs[f"Servo{i}{value}"] = v
            sigs[f"Servo{i}{flag}"] = int(fl)
        return "s2n", f"{'ServoTargetAngle' if a else 'ServoTargetCurrent'}_S{s:02d}", sigs
    if isinstance(f, nr.EnumRequest):
        return "s2n", "EnumRequest", {}
    if isinstance(f, nr.EnumResponse):
        return "n2s", f"EnumResponse_S{s:02d}", {}
    if isinstance(f, nr.InitialConfigRequest):
        return "s2n", f"InitialConfigRequest_S{s:02d}", {}
    if isinstance(f, nr.BoardConfig):
        sigs = {"SubCommand": int(f.COMMAND)}
        for field, signal in _BOARD_SIGNALS[type(f).__name__].items():
            sigs[signal] = int(getattr(f, field))
        return "s2n", f"BoardConfigRequest_S{s:02d}", sigs
    d = f.as_dict()
    d.pop("kind")
    d.pop("slave")
    sigs = {camel(k): int(v) for k, v in d.items()}
    if isinstance(f, nr.ServoState):
        return (
            "n2s",
            f"ServoState{f.index}_S{s:02d}",
            {k: v for k, v in sigs.items() if k != "Index"},
        )
    return "n2s", f"{type(f).__name__}_S{s:02d}", sigs


@settings(max_examples=1500, deadline=None)
@given(FRAMES)
def test_codec_matches_cantools_both_ways(dbs, frame):
    db_key, name, signals = dbc_view(frame)
    msg = dbs[db_key].get_message_by_name(name)
    ours = frame.encode()
    assert msg.frame_id == frame.can_id
    assert len(ours) <= msg.length
    # cantools encode (strict range checks) == our bytes zero-padded to the DBC length
    full = dict(signals)
    for sig in msg.signals:  # servo-word frames shorter than 4 servos: pad with zeros
        if not sig.multiplexer_ids:
            full.setdefault(sig.name, 0)
    theirs = msg.encode(full, scaling=False)
    assert theirs == ours + bytes(msg.length - len(ours))
    # cantools decode of our (possibly short) frame == the signals we meant
    decoded = msg.decode(ours, scaling=False, decode_choices=False, allow_truncated=True)
    assert decoded == signals
    # our decoder recovers the dataclass, given the transmit direction
    again = nr.decode_frame(frame.can_id, ours, frame.DIRECTION)
    assert again == frame


@settings(max_examples=300, deadline=None)
@given(st.builds(nr.ImuFrame, slaves, st.sampled_from(list(nr.ImuMessage)), i16, i16, i16))
def test_imu_scaling_matches_dbc_factors(dbs, f):
    _, name, _ = dbc_view(f)
    scaled = dbs["n2s"].get_message_by_name(name).decode(f.encode())
    kind = f.sensor.name.capitalize()
    sx, sy, sz = scaled[f"{kind}X"], scaled[f"{kind}Y"], scaled[f"{kind}Z"]
    expected = (-sx, sy, -sz) if f.sensor == nr.ImuMessage.MAG else (-sy, sx, sz)
    assert f.spinal_frame() == pytest.approx(expected, rel=1e-12, abs=1e-12)


def test_bus_view_decodes_neuron_frames_and_config_request(dbs):
    bus = dbs["bus"]
    state = nr.ServoState(3, 1, -5, 40, False, True, False, 12, 0)
    assert bus.decode_message(state.can_id, state.encode(), scaling=False)["Current"] == 12
    req = nr.InitialConfigRequest(3)
    assert bus.get_message_by_frame_id(req.can_id).name == "InitialConfig0_S03"
    assert bus.decode_message(req.can_id, b"", allow_truncated=True) == {}
    pwm = nr.pack_pwm([100] * 7)
    for frame in pwm:
        assert set(bus.decode_message(frame.can_id, frame.encode()).values()) <= {100, 0}


def test_generator_output_is_committed(tmp_path):
    """The DBCs in the repo equal what generate_dbc.py writes (no hand edits drift)."""
    import runpy
    import shutil

    shutil.copy(DBC_DIR / "generate_dbc.py", tmp_path / "generate_dbc.py")
    runpy.run_path(str(tmp_path / "generate_dbc.py"), run_name="__main__")
    for name in ("neuron.dbc", "neuron_spinal_to_neuron.dbc", "neuron_neuron_to_spinal.dbc"):
        assert (tmp_path / name).read_text() == (DBC_DIR / name).read_text()
