"""The fuzzing campaign's short form (docs/fuzzing.md; the full one is scripts/fuzz.sh).

Every Python target replays its committed corpus (fuzz/corpus/<target>/, seeded from the
firmware_protocol/ golden vectors) and then runs 1,500 new inputs (seeded mutations of the
corpus mixed with the target's structure-aware generator): no crash, no hang, no finding
(a bad-checksum frame accepted, a frame not re-encoding to its bytes, a NaN where the
format has none, counters that disagree). The Rust targets' corpora are replayed through
the bindings that call the same parse functions: the rosserial scan (FrameParser), the
Leptrino OK-sample scan (LeptrinoStreamParser.feed_ok_samples), the Neuron receive paths
(NeuronBank: Spinal -> Neuron; CanMaster: Neuron -> Spinal) against the Python reference
codec, the description loader (in a child process). Known open findings have a strict
xfail test each with their committed reproducer (fuzz/regressions/).
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import can
import pytest

ROOT = Path(__file__).resolve().parents[1]
FUZZ_PY = ROOT / "fuzz" / "python"
sys.path.insert(0, str(FUZZ_PY))

import engines  # noqa: E402
from fuzz_targets import TARGETS  # noqa: E402
from fuzz_targets.known import KNOWN  # noqa: E402

from rdm import _rdm  # noqa: E402
from rdm.nodes.neuron_bank import NeuronSpec  # noqa: E402
from rdm.nodes.servo_model import ServoConfig  # noqa: E402
from rdm.protocol.neuron import Direction, NeuronFrameError, decode_candidates  # noqa: E402

CORPUS = ROOT / "fuzz" / "corpus"
REGRESSIONS = ROOT / "fuzz" / "regressions"
NEW_INPUTS = 1500


def corpus(name: str) -> list[bytes]:
    items = [p.read_bytes() for p in sorted((CORPUS / name).iterdir())]
    assert items, f"fuzz/corpus/{name} is empty"
    return items


def failures(outcome: engines.Outcome) -> list[str]:
    return (
        outcome.crashes
        + [f"{k}: {n}" for k, n in outcome.findings.items()]
        + ([f"{outcome.hangs} hangs"] if outcome.hangs else [])
    )


@pytest.mark.parametrize("name", sorted(TARGETS))
def test_corpus_replays_clean(name):
    target = TARGETS[name]
    out = engines.Outcome()
    worker = engines._Worker(name, 30.0) if target.isolated else None
    try:
        for data in corpus(name):
            kind, message = worker.run(data) if worker else engines.run_one(target, data, 30.0)
            if kind:  # known open findings are not in the corpus either
                out.record(kind if not kind.startswith("known:") else "crash", message, data)
    finally:
        if worker is not None:
            worker.close()
    assert not failures(out), failures(out)


@pytest.mark.parametrize("name", sorted(TARGETS))
def test_new_inputs(name):
    out = engines.run_mutations(TARGETS[name], corpus(name), NEW_INPUTS, seed=28, timeout=30.0)
    assert out.runs == NEW_INPUTS
    assert not failures(out), (failures(out), out.reproducers[:1])


def test_harness_rosserial_oracle_on_the_fact_sheet_examples():
    """The harness's own frame rule and encoder are not vacuous: they reproduce the fact
    sheet's literal frames (golden_frames.json, fact_sheet_examples) and refuse each with
    its message or length checksum off by one."""
    import json

    from fuzz_targets.base import rosserial_frame, rosserial_frame_ok

    from rdm.protocol.rosserial.registry import spinal_msgs_dir

    golden = json.loads((spinal_msgs_dir() / "golden_frames.json").read_text())
    for example in golden["fact_sheet_examples"]:
        raw = bytes.fromhex(example["hex"].replace(" ", ""))
        assert rosserial_frame_ok(raw)
        assert rosserial_frame(example["topic_id"], raw[7:-1]) == raw
        assert not rosserial_frame_ok(raw[:-1] + bytes([(raw[-1] + 1) % 256]))
        assert not rosserial_frame_ok(raw[:4] + bytes([(raw[4] + 1) % 256]) + raw[5:])


def test_candump_timestamp_past_the_double_is_a_syntax_row(tmp_path):
    """A candump -L stamp of 400 digits (float() gives inf) is a counted syntax error, not
    an infinite timestamp in the JSON rows (found by the candump_log target)."""
    from rdm.protocol.neuron import NeuronDecoder, decode_candump

    log = tmp_path / "x.log"
    log.write_text("(" + "1" * 400 + ".5) can0 105#640038FFFF7F R\n"
                   "(1700000000.5) can0 105#640038FFFF7F R\n")  # fmt: skip
    dec = NeuronDecoder()
    rows = list(decode_candump(log, decoder=dec))
    assert [r["ok"] for r in rows] == [False, True]
    assert rows[0]["error"].startswith("syntax: timestamp")
    assert rows[1]["timestamp"] == 1700000000.5
    assert dec.errors["syntax"] == 1


def test_asc_timestamp_past_the_double_is_a_syntax_row(tmp_path):
    from rdm.protocol.neuron import NeuronDecoder, decode_candump

    asc = tmp_path / "x.asc"
    asc.write_text(
        "date Thu Jan 1 00:00:00.000 1970\nbase hex  timestamps absolute\n"
        "internal events logged\nBegin Triggerblock Thu Jan 1 00:00:00.000 1970\n"
        " 0.000000 Start of measurement\n"
        " " + "1" * 400 + ".5 1  105             Rx   d 6 64 00 38 FF FF 7F\n"
        " 0.500000 1  105             Rx   d 6 64 00 38 FF FF 7F\nEnd TriggerBlock\n"
    )
    dec = NeuronDecoder()
    rows = list(decode_candump(asc, decoder=dec))
    assert [r["ok"] for r in rows] == [False, True]
    assert dec.errors["syntax"] == 1


# -- the Rust targets' corpora through the bindings ------------------------------------------
def test_rosserial_scan_corpus_through_the_native_scan():
    """Each input of the Rust target (selector byte, stream) through FrameParser, whose scan
    is rdm_core's next_candidate: every frame it accepts passes the harness's own rule."""
    from fuzz_targets.base import rosserial_frame_ok

    from rdm.protocol.rosserial.framing import Frame, FrameParser

    accepted = 0
    for data in corpus("rosserial_scan"):
        if not data:
            continue  # no selector: the target reads nothing
        selector, stream = data[0], data[1:]
        parser = FrameParser((64, 512, 1022, 65535)[selector & 3], rescan=bool(selector & 4))
        for e in parser.feed(stream):
            if isinstance(e, Frame):
                assert rosserial_frame_ok(stream[e.offset : e.offset + e.size])
                accepted += 1
    assert accepted > 100  # the golden frames are accepted, so the check ran


def test_leptrino_ok_run_corpus_through_the_native_scan():
    from fuzz_targets import leptrino

    for data in corpus("leptrino_ok_run"):
        leptrino.check(data)  # feed vs feed_ok_samples (the Rust run), frames re-found


def _python_reading(can_id: int, data: bytes, direction: Direction) -> tuple[str, str]:
    try:
        frames = decode_candidates(can_id, data, direction)
    except NeuronFrameError as exc:
        return "error", exc.reason
    return "kind", frames[0].KIND


def test_neuron_frame_corpus_rust_receivers_agree_with_the_reference_codec():
    """Each (id, payload) of the Rust target to a Neuron board (NeuronBank, slave 1:
    decode_spinal_to_neuron) and to Spinal's master (CanMaster: decode_neuron_to_spinal):
    the kind or the error reason each counts is the Python reference codec's."""
    bank = _rdm.NeuronBank([NeuronSpec(1, (ServoConfig(dynamixel_id=1),) * 4).core_dict()])
    master = _rdm.CanMaster(boot_delay_ms=0, start_ms=0)
    compared = 0
    for data in corpus("neuron_frame"):
        if len(data) < 2:
            continue  # no id: the target reads nothing
        can_id, payload = data[0] | data[1] << 8, data[2:]
        if can_id > 0x7FF or len(payload) > 8:
            continue
        msg = can.Message(arbitration_id=can_id, data=payload, is_extended_id=False)
        before = bank.board_state(0)
        bank.tick(0.0, [msg])
        after = bank.board_state(0)
        if after["rx_count"] > before["rx_count"]:  # addressed to slave 1 or broadcast
            kind, what = _python_reading(can_id, payload, Direction.SPINAL_TO_NEURON)
            counts = after["rx_kinds" if kind == "kind" else "rx_errors"]
            old = before["rx_kinds" if kind == "kind" else "rx_errors"]
            assert counts.get(what, 0) == old.get(what, 0) + 1, (hex(can_id), payload, what)
            compared += 1
        errors, kinds = dict(master.rx_errors()), dict(master.rx_kinds())
        master.tick_ms(0, [msg])
        kind, what = _python_reading(can_id, payload, Direction.NEURON_TO_SPINAL)
        counts, old = (dict(master.rx_kinds()), kinds) if kind == "kind" else (
            dict(master.rx_errors()), errors)  # fmt: skip
        if kind == "kind" and counts.get(what, 0) == old.get(what, 0):
            continue  # accepted by the codec, then refused by the master (unknown slave)
        assert counts.get(what, 0) == old.get(what, 0) + 1, (hex(can_id), payload, what)
        compared += 1
    assert compared > 20


def test_description_corpus_loads_in_a_child():
    """The Rust target's corpus through the bindings' loader, in a child process."""
    for data in corpus("description"):
        kind, message = _isolated("description", data)
        assert kind == "", message


def _isolated(name: str, data: bytes) -> tuple[str, str]:
    worker = engines._Worker(name, 60.0)
    try:
        return worker.run(data)
    finally:
        worker.close()


# -- known open findings: strict xfail with the committed reproducer --------------------------
def test_every_known_finding_has_a_reproducer():
    names = {k.name for k in KNOWN}
    assert names == set()  # every finding is closed (docs/fuzzing.md)
    for k in KNOWN:
        assert list((REGRESSIONS / k.target).iterdir()), k.name


def test_ground_verifier_refuses_a_huge_integer_t():
    """A signed datagram whose t is a 400-digit integer gets a verdict (stale), not an
    OverflowError out of Verifier.verify (which would end the onboard node's port)."""
    from fuzz_targets.ground import KEY, T0

    from rdm.ground.auth import Verifier

    data = (REGRESSIONS / "ground_verify" / "t-400-digit-int").read_bytes()
    for key in (KEY, None):
        assert Verifier(key).verify(data, T0).kind == "rejected"


def test_urdf_nested_20000_deep_is_refused_with_a_message():
    """rdm model --urdf deep.urdf: the loader names the file and the nesting before the XML
    parser (which recurses per level) sees it, and the process lives."""
    data = (REGRESSIONS / "description" / "urdf-nested-20000").read_bytes()
    code = (
        "import sys; sys.path.insert(0, sys.argv[1]); from fuzz_targets.description import split;"
        "from rdm import _rdm; from rdm.model import DescriptionError\n"
        "u, t = split(open(sys.argv[2], 'rb').read())\n"
        "try:\n    _rdm.Robot.from_strs(u, t, 'deep.urdf', 'x.toml')\n"
        "except DescriptionError as e:\n    print(e)\n"
    )
    path = REGRESSIONS / "description" / "urdf-nested-20000"
    proc = subprocess.run([sys.executable, "-c", code, str(FUZZ_PY), str(path)],
                          capture_output=True, text=True, timeout=120, check=False)  # fmt: skip
    assert len(data) < 11_000  # the macro form; the text is ~70 KB
    assert proc.returncode == 0 and proc.stdout.startswith("deep.urdf"), proc.returncode


def test_origin_near_the_double_limit_is_refused():
    """A joint origin of -1e308 m is finite, but the model's products of it overflow (NaN
    inertia at q = 0): the loader refuses it, naming the joint, the attribute and the rule."""
    from fuzz_targets.description import split

    from rdm.model import DescriptionError

    urdf, toml = split((REGRESSIONS / "description" / "origin-1e308").read_bytes())
    with pytest.raises(DescriptionError) as err:
        _rdm.Robot.from_strs(urdf, toml, "x.urdf", "x.toml")
    assert str(err.value) == (
        "x.urdf: joint 'alpha1'/<origin xyz>: -1e308 is outside the length bound |x| <= 1000 m"
    )
