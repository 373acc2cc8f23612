"""``rdm decode`` on UART captures with valid and corrupt frames; format registry behaviour."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from rdm.cli import main
from rdm.commands.decode import FORMATS, detect_format

REPO = Path(__file__).resolve().parents[1]
SPINAL = REPO / "firmware_protocol" / "spinal"
sys.path.insert(0, str(SPINAL / "tools"))
import rosbags_oracle as oracle  # noqa: E402

GOLDEN = json.loads((SPINAL / "golden_frames.json").read_text())
TS = oracle.make_typestore()


def hexframe(vec: dict) -> bytes:
    return bytes.fromhex(vec["hex"])


def topic_vec(topic: str, k: int = 0) -> dict:
    return [v for v in GOLDEN["topics"] if v["topic"] == topic][k]


def build_capture():
    """Return capture bytes and the expected (offset, kind/error) sequence."""
    parts: list[tuple[bytes, tuple]] = []
    parts.append((hexframe(GOLDEN["reserved"][0]), ("time", "std_msgs/Time")))
    imu = topic_vec("imu")
    parts.append((hexframe(imu), ("message", "imu")))
    parts.append((b"\x13\x37\x00", ("skipped", None)))
    broken = bytearray(hexframe(topic_vec("four_axes/command")))
    broken[10] ^= 0x40
    parts.append((bytes(broken), ("bad", "message_checksum")))
    cmd = topic_vec("four_axes/command", 1)
    parts.append((hexframe(cmd), ("message", "four_axes/command")))
    log = GOLDEN["reserved"][1]
    parts.append((hexframe(log), ("log", "rosserial_msgs/Log")))
    offsets, data = [], b""
    for raw, what in parts:
        offsets.append((len(data), what))
        data += raw
    truncated = hexframe(topic_vec("baro"))[:12]
    offsets.append((len(data), ("bad", "truncated")))
    data += truncated
    return data, offsets, imu, cmd, log


def test_decode_uart_text_lines(tmp_path, capsys):
    data, expected, imu, _cmd, _log = build_capture()
    path = tmp_path / "spinal.bin"
    path.write_bytes(data)
    assert main(["decode", str(path)]) == 0
    out = capsys.readouterr()
    lines = out.out.strip().splitlines()
    assert len(lines) == len(expected)
    for line, (offset, (kind, detail)) in zip(lines, expected, strict=True):
        assert line.startswith(f"@{offset} ")
        if kind == "bad":
            assert f"BAD {detail}" in line
        elif kind == "skipped":
            assert "BAD 3 bytes outside any frame" in line
        else:
            assert f" {kind} " in line and detail in line
    imu_line = lines[1]
    assert "id=153 imu [spinal/Imu]" in imu_line
    assert json.loads(imu_line.split("] ", 1)[1]) == imu["fields"]
    assert "uart: 4 records decoded, 3 bad" in out.err
    assert "'message_checksum': 1" in out.err and "'skipped': 1" in out.err


def test_decode_uart_json_lines(tmp_path, capsys):
    data, expected, imu, cmd, log = build_capture()
    path = tmp_path / "capture.raw"
    path.write_bytes(data)
    assert main(["decode", "--json", str(path)]) == 0
    recs = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert [r["offset"] for r in recs] == [o for o, _ in expected]
    by_topic = {r.get("topic"): r for r in recs if r["ok"]}
    assert by_topic["imu"]["fields"] == imu["fields"]
    assert by_topic["four_axes/command"]["fields"] == cmd["fields"]
    assert by_topic["four_axes/command"]["topic_id"] == 108
    assert by_topic["log"]["fields"] == log["fields"]
    errors = [r["error"] for r in recs if not r["ok"]]
    assert errors == ["3 bytes outside any frame", "message_checksum", "truncated"]


def test_bad_frame_lines_are_the_golden_text(tmp_path, capsys):
    """A corrupt frame's line in both forms, written out by hand: the human line's detail and
    the JSON line are json.dumps's default text with the keys in the record's order
    (offset, kind, ok, error, bytes)."""
    frame = bytearray(hexframe(topic_vec("four_axes/command")))
    frame[10] ^= 0x40
    path = tmp_path / "bad.bin"
    path.write_bytes(bytes(frame))
    hexed = bytes(frame).hex()
    assert main(["decode", str(path)]) == 0
    text = capsys.readouterr().out
    assert text == f'@0 BAD message_checksum {{"kind": "bad_frame", "bytes": "{hexed}"}}\n'
    assert main(["decode", "--json", str(path)]) == 0
    text = capsys.readouterr().out
    assert text == (
        '{"offset": 0, "kind": "bad_frame", "ok": false, "error": "message_checksum", '
        f'"bytes": "{hexed}"}}\n'
    )


def test_decode_learns_ids_from_the_handshake_and_flags_md5_mismatch(tmp_path, capsys):
    reply = [hexframe(v) for v in GOLDEN["handshake"]["client_reply"]]
    # a device whose ids differ from the default layout: imu announced on id 170
    info = {
        "topic_id": 170,
        "topic_name": "imu",
        "message_type": "spinal/Imu",
        "md5sum": "ae078a6cf2a27bba55c15c4ea83c6817",
        "buffer_size": 1024,
    }
    moved = oracle.frame(0, oracle.serialize(TS, "rosserial_msgs/msg/TopicInfo", info))
    wrong = dict(info, topic_id=171, topic_name="baro", message_type="spinal/Barometer")
    wrong_md5 = oracle.frame(0, oracle.serialize(TS, "rosserial_msgs/msg/TopicInfo", wrong))
    imu = topic_vec("imu")
    imu_170 = oracle.frame(170, hexframe(imu)[7:-1])
    baro_171 = oracle.frame(171, hexframe(topic_vec("baro"))[7:-1])
    path = tmp_path / "handshake.uart"
    path.write_bytes(b"".join(reply) + moved + wrong_md5 + imu_170 + baro_171)
    assert main(["decode", "--json", "--no-layout", str(path)]) == 0
    recs = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert len(recs) == len(reply) + 4
    infos = [r for r in recs if r["kind"] == "topic_info"]
    assert len(infos) == 39 and all(r["ok"] for r in infos[:38])
    assert not infos[38]["ok"] and "md5" in infos[38]["error"]
    assert recs[-2]["topic"] == "imu" and recs[-2]["fields"] == imu["fields"]
    assert not recs[-1]["ok"] and recs[-1]["error"] == "refused (md5 or type)"


def test_without_layout_unknown_ids_are_reported(tmp_path, capsys):
    path = tmp_path / "x.bin"
    path.write_bytes(hexframe(topic_vec("imu")))
    assert main(["decode", "--json", "--no-layout", str(path)]) == 0
    (rec,) = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert rec == {
        "offset": 0,
        "kind": "message",
        "ok": False,
        "error": "unknown topic id",
        "topic_id": 153,
        "topic": None,
        "type": None,
        "payload": hexframe(topic_vec("imu"))[7:-1].hex(),
    }


def test_format_registry_and_detection(tmp_path, capsys):
    assert set(FORMATS) == {"uart", "candump", "leptrino"}
    assert detect_format(Path("a.bin")) == "uart"
    assert detect_format(Path("a.log")) == "candump"
    assert detect_format(Path("a.lep")) == "leptrino"
    assert detect_format(Path("a.txt")) is None
    odd = tmp_path / "capture.txt"
    odd.write_bytes(b"")
    assert main(["decode", str(odd)]) == 2
    assert "--format" in capsys.readouterr().err
    assert main(["decode", "--format", "uart", str(odd)]) == 0
    assert main(["decode", str(tmp_path / "missing.bin")]) == 2
    assert "no such file" in capsys.readouterr().err


def test_missing_other_decoders_give_a_clear_error(tmp_path, capsys, monkeypatch):
    # None in sys.modules makes the import fail, as in an installation without those modules
    monkeypatch.setitem(sys.modules, "rdm.protocol.neuron", None)
    monkeypatch.setitem(sys.modules, "rdm.protocol.leptrino", None)
    log = tmp_path / "can.log"
    log.write_text("(0.0) vcan0 123#00\n")
    assert main(["decode", str(log)]) == 2
    assert "rdm.protocol.neuron.decode_candump is not available" in capsys.readouterr().err
    lep = tmp_path / "ft.lep"
    lep.write_bytes(b"\x10\x02")
    assert main(["decode", "--format", "leptrino", str(lep)]) == 2
    assert "rdm.protocol.leptrino.decode_leptrino" in capsys.readouterr().err


def test_leptrino_garbage_between_frames_is_counted(tmp_path, capsys):
    """Bytes outside any frame are reported (one bad record with their number), not dropped
    silently: 300 random bytes without a DLE (0x10), a frame, 200 more."""
    from rdm.protocol import leptrino as lp

    rng = np.random.default_rng(3)
    junk = [bytes(b for b in rng.integers(0, 256, n, np.uint8).tobytes() if b != 0x10)
            for n in (300, 200)]  # fmt: skip
    frame = lp.encode_response(lp.ForceData((1, 2, 3, 4, 5, 6), 25, 0))
    lep = tmp_path / "ft.lep"
    lep.write_bytes(junk[0] + frame + junk[1])
    assert main(["decode", "--json", str(lep)]) == 0
    out, err = capsys.readouterr()
    records = [json.loads(line) for line in out.splitlines()]
    assert [r["ok"] for r in records] == [True, False]
    assert records[1]["discarded_bytes"] == len(junk[0]) + len(junk[1])
    assert "1 records decoded, 1 bad {'discarded': 1}" in err


def test_cli_module_entry_point(tmp_path):
    path = tmp_path / "one.bin"
    path.write_bytes(hexframe(GOLDEN["reserved"][0]))
    # the installed package (its compiled extension included), in a bare environment
    out = subprocess.run(
        [sys.executable, "-m", "rdm.cli", "decode", "--json", str(path)],
        capture_output=True,
        text=True,
        env={"PATH": "/usr/bin:/bin"},
        check=True,
        cwd=tmp_path,
    )
    rec = json.loads(out.stdout)
    assert rec["kind"] == "time" and rec["fields"] == {
        "data": {"sec": 1767225600, "nsec": 250000000}
    }


@pytest.mark.parametrize("chunk", [b"\xff" * 50, b"\xff\xfe" * 30, bytes(range(256))])
def test_decode_never_crashes_on_junk(tmp_path, capsys, chunk):
    path = tmp_path / "junk.bin"
    path.write_bytes(chunk)
    assert main(["decode", "--json", str(path)]) == 0
    recs = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert recs and not any(r["ok"] for r in recs)


def test_a_reader_that_stops_early_ends_the_command_quietly(tmp_path):
    """``rdm decode x.log | head -1``: the exit status a shell gives a filter killed by SIGPIPE
    (141), no traceback."""
    log = tmp_path / "many.log"
    log.write_text("".join(f"({k / 1000:.6f}) can0 0F#{k % 256:02X}\n" for k in range(50_000)))
    proc = subprocess.Popen(
        [sys.executable, "-m", "rdm.cli", "decode", str(log)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    assert proc.stdout is not None and proc.stderr is not None
    first = proc.stdout.readline()
    proc.stdout.close()  # the reader goes away with ~50k lines still to print
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=120) == 141
    assert first.startswith(b"line 1 ")
    assert "Traceback" not in err and "BrokenPipeError" not in err


def test_a_folder_needs_mcap(tmp_path, capsys):
    assert main(["decode", str(tmp_path)]) == 2
    assert "--mcap OUT converts a run folder" in capsys.readouterr().err
    assert main(["decode", str(tmp_path), "--mcap", str(tmp_path / "w.mcap")]) == 2
    assert "holds no can.log" in capsys.readouterr().err
    capture = tmp_path / "x.device_tx.bin"
    capture.write_bytes(bytes.fromhex(GOLDEN["topics"][0]["hex"]))
    assert main(["decode", str(capture), "--mcap", str(tmp_path / "w.mcap")]) == 2
    assert "no time index beside it (x.device_tx.bin.idx)" in capsys.readouterr().err
    notes = tmp_path / "notes.txt"
    notes.write_text("not a capture")
    assert main(["decode", str(notes), "--mcap", str(tmp_path / "w.mcap")]) == 2
    assert "cannot tell the format" in capsys.readouterr().err
    assert not (tmp_path / "w.mcap").exists()
