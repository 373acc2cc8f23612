"""Spinal message definitions: md5 sums and ROS1 bytes against rosbags and the fact sheet."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from rosbags.typesys.base import Nodetype

from rdm.protocol.rosserial.codec import DecodeError, EncodeError, message_to_dict
from rdm.protocol.rosserial.framing import FrameParser, encode_frame
from rdm.protocol.rosserial.msgdef import MsgDefError, parse_msg, parse_srv
from rdm.protocol.rosserial.registry import TypeRegistry, spinal_registry

SPINAL = Path(__file__).resolve().parents[1] / "firmware_protocol" / "spinal"
sys.path.insert(0, str(SPINAL / "tools"))
import rosbags_oracle as oracle  # noqa: E402

TS = oracle.make_typestore()
REG = spinal_registry()
MD5SUMS = json.loads((SPINAL / "md5sums.json").read_text())
GOLDEN = json.loads((SPINAL / "golden_frames.json").read_text())


def test_every_definition_file_is_loaded():
    msgs = {f"{p.parts[-3]}/{p.stem}" for p in SPINAL.glob("*/msg/*.msg")}
    srvs = {f"{p.parts[-3]}/{p.stem}" for p in SPINAL.glob("*/srv/*.srv")}
    assert len(msgs) >= 37 and len(srvs) == 7
    assert msgs <= set(REG.message_names)
    assert srvs == set(REG.service_names)


@pytest.mark.parametrize("name", sorted(MD5SUMS["messages"]))
def test_message_md5_equals_fact_sheet_and_rosbags(name):
    ours = REG.md5(name)
    assert ours == MD5SUMS["messages"][name]
    assert ours == oracle.md5(TS, oracle.rosbags_name(name))


@pytest.mark.parametrize("name", sorted(MD5SUMS["services"]))
def test_service_md5_equals_fact_sheet_and_rosbags(name):
    srv = REG.srv(name)
    ref = MD5SUMS["services"][name]
    assert (srv.md5, srv.request_md5, srv.response_md5) == (
        ref["service"],
        ref["request"],
        ref["response"],
    )
    assert srv.request_md5 == oracle.md5(TS, oracle.rosbags_name(name) + "Request")
    assert srv.response_md5 == oracle.md5(TS, oracle.rosbags_name(name) + "Response")


def test_every_spinal_message_has_a_fact_sheet_md5():
    spinal = {n for n in REG.message_names if n.startswith("spinal/") and "Re" not in n[-8:]}
    assert spinal <= set(MD5SUMS["messages"]), spinal - set(MD5SUMS["messages"])
    assert len([n for n in MD5SUMS["messages"] if n.startswith("spinal/")]) == 31


def test_constants_become_class_attributes():
    assert REG.msg("spinal/FlightConfigCmd").cls.INTEGRATION_CONTROL_OFF_CMD == 161
    assert REG.msg("spinal/UavInfo").cls.DRAGON == 32
    assert REG.msg("spinal/SetBoardConfigRequest").cls.SET_SERVO_PULLEY_SKIP_THRESH == 12
    assert REG.msg("rosserial_msgs/TopicInfo").cls.ID_TX_STOP == 11


# -- hypothesis strategies built from rosbags' field definitions (not from our parser) -----
_INT_RANGES = {
    "int8": (-(2**7), 2**7 - 1),
    "uint8": (0, 2**8 - 1),
    "int16": (-(2**15), 2**15 - 1),
    "uint16": (0, 2**16 - 1),
    "int32": (-(2**31), 2**31 - 1),
    "uint32": (0, 2**32 - 1),
    "int64": (-(2**63), 2**63 - 1),
    "uint64": (0, 2**64 - 1),
}


def _base(base: str) -> st.SearchStrategy:
    if base in _INT_RANGES:
        lo, hi = _INT_RANGES[base]
        return st.integers(lo, hi)
    if base == "bool":
        return st.booleans()
    if base == "float32":
        return st.floats(width=32, allow_nan=False)
    if base == "float64":
        return st.floats(allow_nan=False)
    if base == "string":
        return st.text(st.characters(exclude_categories=("Cs",)), max_size=12)
    raise AssertionError(base)


def _node(node: tuple) -> st.SearchStrategy:
    kind, spec = node
    if kind == Nodetype.BASE:
        return _base(spec[0])
    if kind == Nodetype.NAME:
        if spec in (oracle.TIME, oracle.DURATION):
            return st.fixed_dictionaries(
                {"sec": st.integers(0, 2**31 - 1), "nsec": st.integers(0, 999_999_999)}
            )
        return fields_strategy(spec)
    sub, count = spec
    if kind == Nodetype.ARRAY:
        return st.lists(_node(sub), min_size=count, max_size=count)
    return st.lists(_node(sub), max_size=5)


def fields_strategy(rosbags_type: str) -> st.SearchStrategy:
    _consts, defs = TS.fielddefs[rosbags_type]
    return st.fixed_dictionaries(
        {name: _node(node) for name, node in defs if name != oracle.PLACEHOLDER}
    )


ALL_TYPES = [n for n in REG.message_names if n != "std_msgs/Header"]


@pytest.mark.parametrize("name", ALL_TYPES)
def test_serialization_equals_rosbags_and_round_trips(name):
    codec = REG.msg(name)
    rb_name = oracle.rosbags_name(name)

    @settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
    @given(fields_strategy(rb_name))
    def check(fields):
        ours = codec.encode(fields)
        assert ours == oracle.serialize(TS, rb_name, fields)
        back = codec.decode(ours)
        assert isinstance(back, codec.cls)
        assert message_to_dict(back) == fields
        assert codec.encode(back) == ours

    check()


def test_golden_topic_frames_encode_and_decode():
    parser = FrameParser(1022)
    for vec in GOLDEN["topics"] + GOLDEN["reserved"] + GOLDEN["handshake"]["client_reply"]:
        raw = bytes.fromhex(vec["hex"])
        payload = b"" if vec["type"] is None else REG.msg(vec["type"]).encode(vec["fields"])
        assert encode_frame(vec["topic_id"], payload) == raw, vec["name"]
        (frame,) = parser.feed(raw)
        assert frame.topic_id == vec["topic_id"]
        if vec["type"] is not None:
            assert message_to_dict(REG.msg(vec["type"]).decode(frame.payload)) == vec["fields"]


def test_decode_rejects_truncated_and_trailing_bytes():
    codec = REG.msg("spinal/FourAxisCommand")
    raw = codec.encode(codec.new(base_thrust=[1.0, 2.0]))
    for cut in range(len(raw)):
        with pytest.raises(DecodeError):
            codec.decode(raw[:cut])
    with pytest.raises(DecodeError, match="trailing"):
        codec.decode(raw + b"\x00")
    # a count claiming more elements than bytes left fails before allocating anything
    with pytest.raises(DecodeError, match="base_thrust"):
        codec.decode(bytes(12) + b"\xff\xff\xff\x7f")
    nested = REG.msg("spinal/RollPitchYawTerms")
    with pytest.raises(DecodeError, match="count"):
        nested.decode(b"\xff\xff\xff\xff" + bytes(14))


def test_encode_errors_name_the_field():
    codec = REG.msg("spinal/FourAxisCommand")
    with pytest.raises(EncodeError, match=r"FourAxisCommand\.angles.*exactly 3"):
        codec.encode(codec.new(angles=[0.0, 1.0]))
    pwms = REG.msg("spinal/Pwms")
    with pytest.raises(EncodeError, match=r"Pwms\.motor_value"):
        pwms.encode(pwms.new(motor_value=[70000]))
    with pytest.raises(EncodeError, match="missing field"):
        pwms.encode({})
    imu = REG.msg("spinal/Imu")
    with pytest.raises(EncodeError, match=r"Imu\.stamp"):
        imu.encode(imu.new(stamp="now"))


def test_msgdef_parser_errors_and_rules():
    with pytest.raises(MsgDefError, match="line 2"):
        parse_msg("p/T", "uint8 a\nuint8\n")
    with pytest.raises(MsgDefError, match="---"):
        parse_srv("p/S", "uint8 a\n")
    spec = parse_msg("p/T", "Header h\nOther[] o # comment\nstring S=a # kept\nint8 K = -3 # c\n")
    assert [f.base_type for f in spec.fields] == ["std_msgs/Header", "p/Other"]
    assert [(c.name, c.value) for c in spec.constants] == [("S", "a # kept"), ("K", -3)]


def test_registry_from_another_directory(tmp_path):
    (tmp_path / "demo" / "msg").mkdir(parents=True)
    (tmp_path / "demo" / "msg" / "Pair.msg").write_text("int16 a\nfloat64 b\n")
    reg = TypeRegistry.from_directory(tmp_path)
    codec = reg.msg("demo/Pair")
    assert codec.encode(codec.new(a=-2, b=0.5)) == bytes.fromhex("feff000000000000e03f")


def test_golden_file_is_what_rosbags_generates_from_the_msg_tree():
    import generate_vectors

    assert generate_vectors.build() == GOLDEN
