"""The ground link's datagram rules (``rdm.ground.message``) at their edges, against the
rules as the protocol states them (docs/flying.md): the size limit closed at MAX_DATAGRAM, the
depth limit closed at MAX_DEPTH, duplicate keys malformed, seq in [0, 2**63), and each field's
refusal naming that field first. Catches ``>=`` for ``>``, a dropped duplicate-key hook, a
shifted range edge."""

from __future__ import annotations

import json

import pytest

from rdm.ground.message import (
    MAX_DATAGRAM,
    MAX_DEPTH,
    SEQ_LIMIT,
    Reason,
    Rejected,
    check_command,
    decode,
    json_depth,
)


def command(**change) -> dict:
    msg = {"v": 1, "src": "op", "seq": 1, "t": 100.0, "cmd": "land", "args": {}}
    msg.update(change)
    return msg


def padded(size: int) -> bytes:
    """A valid command of exactly ``size`` bytes (padding in the src-free args string)."""
    base = json.dumps(command(args={"pad": ""}), separators=(",", ":")).encode()
    pad = size - len(base)
    assert pad >= 0
    return json.dumps(command(args={"pad": "x" * pad}), separators=(",", ":")).encode()


def test_the_size_limit_is_closed_at_max_datagram() -> None:
    assert check_command(decode(padded(MAX_DATAGRAM)))["cmd"] == "land"
    with pytest.raises(Rejected) as err:
        decode(padded(MAX_DATAGRAM + 1))
    assert err.value.reason is Reason.TOO_LARGE


def test_the_depth_limit_is_closed_at_max_depth() -> None:
    deep = lambda n: ("[" * n + "1" + "]" * n).encode()  # noqa: E731
    text = b'{"a":' + deep(MAX_DEPTH - 1) + b"}"
    assert json_depth(text) == MAX_DEPTH
    decode(text)
    over = b'{"a":' + deep(MAX_DEPTH) + b"}"
    assert json_depth(over) == MAX_DEPTH + 1
    with pytest.raises(Rejected) as err:
        decode(over)
    assert err.value.reason is Reason.TOO_DEEP
    assert json_depth(b"1") == 0 and json_depth(b'"[[["') == 0  # brackets in strings


def test_duplicate_keys_are_malformed_at_any_level() -> None:
    for text in (b'{"seq":1,"seq":2}', b'{"args":{"h":1,"h":2}}'):
        with pytest.raises(Rejected, match="duplicate key") as err:
            decode(text)
        assert err.value.reason is Reason.MALFORMED


@pytest.mark.parametrize(
    ("seq", "ok"),
    [
        (0, True),
        (SEQ_LIMIT - 1, True),
        (-1, False),
        (SEQ_LIMIT, False),
        (True, False),
        (1.5, False),
    ],
)
def test_seq_is_an_integer_in_zero_to_two_to_the_63(seq, ok) -> None:
    if ok:
        assert check_command(command(seq=seq))["seq"] == seq
    else:
        with pytest.raises(Rejected, match=r"^malformed: seq: "):
            check_command(command(seq=seq))


@pytest.mark.parametrize(
    ("change", "field"),
    [
        ({"v": 2}, "v"),
        ({"src": ""}, "src"),
        ({"src": "x" * 65}, "src"),
        ({"t": "now"}, "t"),
        ({"cmd": "Land"}, "cmd"),
        ({"args": [1]}, "args"),
    ],
)
def test_each_refusal_names_its_field_first(change, field) -> None:
    with pytest.raises(Rejected) as err:
        check_command(command(**change))
    assert err.value.reason is Reason.MALFORMED
    assert err.value.detail.startswith(f"{field}: must be")
    assert str(err.value) == f"malformed: {err.value.detail}"


def test_unknown_fields_and_non_objects_are_named() -> None:
    with pytest.raises(Rejected, match="unknown field 'zzz'"):
        check_command(command(zzz=1))
    with pytest.raises(Rejected, match="not a JSON object but list"):
        check_command([1])
