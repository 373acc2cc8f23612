"""The ground link's verifier (``rdm.ground.auth.Verifier``) verdict by verdict: every field of
each kind (accepted, duplicate, rejected before and after the sender is known) against what
the datagram's own bytes say (``json.loads``), signatures from ``hmac.new``, the time window
at its edge on the retry path as on the first one, and the unsigned (``--insecure-control``)
form's hmac rules. Written to catch the one-line slips a mutation campaign plants: a verdict
that drops its seq or src, a window test with ``>=``, an ``and`` turned into ``or``."""

from __future__ import annotations

import hashlib
import hmac
import json

import pytest

from rdm.ground import auth, message
from rdm.ground.auth import Verdict, Verifier
from rdm.ground.message import Reason

KEY = bytes(range(32))
NOW = 5000.0


def raw(fields: dict) -> bytes:
    """A datagram's bytes with the hmac of ``hmac.new`` over the canonical form (the ground
    protocol's sorted, compact JSON) of the other fields."""
    body = {k: v for k, v in fields.items() if k != "hmac"}
    canonical = json.dumps(body, sort_keys=True, separators=(",", ":")).encode()
    mac = hmac.new(KEY, canonical, hashlib.sha256).hexdigest()
    return json.dumps({**body, "hmac": mac}, sort_keys=True, separators=(",", ":")).encode()


def fields(seq: int = 7, t: float = NOW, src: str = "op", cmd: str = "land") -> dict:
    return {"v": 1, "src": src, "seq": seq, "t": t, "cmd": cmd, "args": {}}


def test_an_accepted_verdict_carries_the_message_its_seq_and_src() -> None:
    data = raw(fields(seq=7, src="ground-1"))
    verdict = Verifier(KEY).verify(data, NOW)
    assert verdict == Verdict("accepted", message=json.loads(data), seq=7, src="ground-1")


@pytest.mark.parametrize(
    ("make", "reason", "detail"),
    [
        (lambda: message.encode(fields()), Reason.UNSIGNED, "no hmac field"),
        (
            lambda: message.encode({**fields(), "hmac": "00" * 32}),
            Reason.BAD_SIGNATURE,
            "hmac does not match the key",
        ),
        (
            lambda: raw(fields(t=NOW + 2.5)),
            Reason.STALE,
            "t is +2.500 s from the robot's clock (window +-2.0 s)",
        ),
        (
            lambda: raw(fields(t=NOW - 3.25)),
            Reason.STALE,
            "t is -3.250 s from the robot's clock (window +-2.0 s)",
        ),
    ],
)
def test_a_rejection_after_parsing_names_its_seq_src_reason_and_rule(make, reason, detail):
    verdict = Verifier(KEY).verify(make(), NOW)
    assert verdict == Verdict("rejected", reason=reason, detail=detail, seq=7, src="op")


def test_a_rejection_before_parsing_has_no_seq_or_src() -> None:
    verdict = Verifier(KEY).verify(b"{not json", NOW)
    assert (verdict.kind, verdict.reason, verdict.seq, verdict.src) == (
        "rejected",
        Reason.MALFORMED,
        None,
        None,
    )


def test_replayed_names_the_sender_and_its_last_seq() -> None:
    v = Verifier(KEY)
    assert v.verify(raw(fields(seq=5)), NOW).kind == "accepted"
    verdict = v.verify(raw(fields(seq=4, cmd="arm")), NOW)
    assert verdict == Verdict(
        "rejected", reason=Reason.REPLAYED, detail="seq 4 not above op's last 5", seq=4, src="op"
    )


def test_a_retry_is_a_duplicate_with_the_remembered_ack_up_to_the_window_edge() -> None:
    """The same bytes again: a duplicate carrying the message, seq, src and the ack kept by
    ``remember_ack``; exactly ``window_s`` after its t still a duplicate, beyond it stale."""
    v = Verifier(KEY)
    data = raw(fields(seq=9, t=NOW))
    assert v.verify(data, NOW).kind == "accepted"
    ack = {"ack": 9, "outcome": "accepted"}
    v.remember_ack("op", 9, ack)
    edge = NOW + auth.WINDOW_S
    assert v.verify(data, edge) == Verdict(
        "duplicate", message=json.loads(data), seq=9, src="op", ack=ack
    )
    late = v.verify(data, edge + 0.001)
    assert (late.kind, late.reason, late.seq, late.src) == ("rejected", Reason.STALE, 9, "op")
    # the first datagram's window has the same closed edge
    assert Verifier(KEY).verify(raw(fields(t=NOW)), edge).kind == "accepted"


def test_unsigned_datagrams_with_or_without_an_hmac_string() -> None:
    """Without a key (``--insecure-control``) an hmac is optional; when given it must be a
    string, and a retry must repeat it to count as a duplicate."""
    v = Verifier(None)
    plain = message.encode(fields(seq=1))
    assert v.verify(plain, NOW).kind == "accepted"
    with_mac = message.encode({**fields(seq=2), "hmac": "ab" * 32})
    assert v.verify(with_mac, NOW).kind == "accepted"
    assert v.verify(with_mac, NOW).kind == "duplicate"
    other_mac = message.encode({**fields(seq=2), "hmac": "cd" * 32})
    assert v.verify(other_mac, NOW).reason is Reason.REPLAYED
    for bad in (5, ["ab"], {"x": 1}):
        verdict = Verifier(None).verify(message.encode({**fields(seq=3), "hmac": bad}), NOW)
        assert (verdict.kind, verdict.reason) == ("rejected", Reason.MALFORMED)
        assert verdict.detail is not None and "hmac" in verdict.detail
        assert (verdict.seq, verdict.src) == (3, "op")


def test_a_full_sender_table_refuses_a_new_sender_by_name() -> None:
    v = Verifier(KEY, max_senders=2)
    for k, src in enumerate(("a", "b")):
        assert v.verify(raw(fields(seq=1, src=src)), NOW + k * 0.1).kind == "accepted"
    verdict = v.verify(raw(fields(seq=1, src="c")), NOW + 0.2)
    assert verdict == Verdict(
        "rejected", reason=Reason.TOO_MANY_SENDERS, detail="2 senders active", seq=1, src="c"
    )
    # the oldest sender is forgotten once its datagrams are all stale (twice the window)
    later = NOW + 2 * auth.WINDOW_S + 0.01
    assert v.verify(raw(fields(seq=1, src="c", t=later)), later).kind == "accepted"
    assert list(v.senders) == ["b", "c"]
