"""Spinal's steady command frames applied in one call (``rdm._rdm.spinal_apply_commands``,
``SpinalMirror._apply_command_run``) against the message handlers, which every frame outside
a leading run (and every subscriber of another layout) takes.

* Random streams of the five command topics (good, rejected, NaN, wrong motor counts, cut
  and extended payloads) mixed with other topics, corrupt bytes and frames split across
  ticks, written by the PC into two mirrors: command runs on, and the message handlers
  only. Oracle: golden runs (``tests/data/spinal_commands.json``, recorded from runs in
  which both mirrors agreed at every tick): each mirror's UART output, diagnostics
  (counters, rejections), controller targets, thrusts and duties after every tick, as
  SHA-256 digests of 50-tick windows. Both forms stay (the call is the path of the leading
  frames of a receive, the handlers that of every other frame), and each must give the
  golden run.
* Servo goals on a running Rust master (a hover stack past the CAN boot): the call against
  the ``servo/target_states`` rules written out, on random index/angle lists, invalid ones
  included.
* The call's declines (a topic it does not take, items that are not good frames) and a
  core rejection handed back as the core's own exception.
"""

from __future__ import annotations

import itertools
import math
import random
import tempfile
from typing import Any

import golden_digests
import numpy as np
import pytest
from test_spinal_busy_ms import _expected_targets

from rdm import _rdm
from rdm.control.attitude import ARM_ON, UAV_HYDRUS
from rdm.nodes import spinal_mirror as sm
from rdm.nodes import spinal_mirror_commands as sm_commands
from rdm.protocol.rosserial import constants as C
from rdm.protocol.rosserial.framing import encode_frame
from rdm.protocol.rosserial.registry import spinal_registry

REG = spinal_registry()
COMMANDS = {
    "four_axes/command": "spinal/FourAxisCommand",
    "rpy/gain": "spinal/RollPitchYawTerms",
    "p_matrix_pseudo_inverse_inertia": "spinal/PMatrixPseudoInverseWithInertia",
    "desire_coordinate": "spinal/DesireCoord",
    "servo/target_states": "spinal/ServoControlCmd",
}
_BUSES = itertools.count()


def _mirror(runs: bool) -> tuple[sm.SpinalMirror, Any]:
    """A mirror on an in-process UART (and the PC's end of it) and a bus of its own;
    without ``runs`` every command goes through the message handlers."""
    from rdm.link.can import open_can
    from rdm.link.uart_pipe import open_inproc_uart

    dev, host = open_inproc_uart()
    bus = open_can(f"virtual:spinal_commands_{next(_BUSES)}")
    mirror = sm.SpinalMirror(dev, bus, boot_delay_ms=0)
    if not runs:
        mirror._command_kinds = bytes(len(mirror._command_kinds))  # no run is armed
    return mirror, host


def _command_payload(topic: str, rng: random.Random) -> bytes:
    codec = REG.msg(COMMANDS[topic])
    if topic == "four_axes/command":
        n = rng.choice([4, 4, 4, 3, 0])
        angles = [rng.choice([0.0, 0.1, -0.3, 2.0]) for _ in range(3)]
        base = [rng.choice([5.0, 9.0, 6.5, 0.0]) for _ in range(n)]
        if rng.random() < 0.15:  # the core's non-finite and range checks
            (angles if rng.random() < 0.5 else base or angles)[0] = rng.choice(
                [math.nan, math.inf, -1.0]
            )
        msg = codec.new(angles=angles, base_thrust=base)
    elif topic == "rpy/gain":
        term = REG.msg("spinal/RollPitchYawTerm")
        motors = [
            term.new(**{f.name: rng.randint(-3000, 3000) for f in term.spec.fields})
            for _ in range(rng.choice([4, 4, 3, 5]))
        ]
        msg = codec.new(motors=motors)
    elif topic == "p_matrix_pseudo_inverse_inertia":
        unit = REG.msg("spinal/PMatrixPseudoInverseUnit")
        rows = [
            unit.new(r=rng.randint(-900, 900), p=rng.randint(-900, 900), y=rng.randint(-900, 900))
            for _ in range(rng.choice([4, 4, 2]))
        ]
        msg = codec.new(pseudo_inverse=rows, inertia=[rng.randint(-50, 200) for _ in range(6)])
    elif topic == "desire_coordinate":
        msg = codec.new(roll=rng.choice([0.0, 0.2, math.nan]), pitch=0.1, yaw=-0.4)
    else:
        n = rng.choice([1, 2, 0])
        msg = codec.new(
            index=[rng.randint(0, 3) for _ in range(n)],
            angles=[rng.randint(-5, 5) for _ in range(n)],
        )
    return codec.encode(msg)


def _piece(rng: random.Random, slots: dict[str, Any]) -> bytes:
    """One frame of the PC's stream (mostly commands), or noise."""
    kind = rng.random()
    if kind < 0.8:
        topic = rng.choice(list(COMMANDS))
        data = _command_payload(topic, rng)
        if rng.random() < 0.08 and data:
            data = data[: rng.randrange(len(data))]  # the codec refuses it: dropped
        elif rng.random() < 0.05:
            data += b"\x00"  # a trailing byte: dropped too
        return encode_frame(slots[topic].topic_id, data)
    if kind < 0.87:
        slot = slots["flight_config_cmd"]
        return encode_frame(slot.topic_id, slot.codec.encode(slot.codec.new(cmd=ARM_ON)))
    if kind < 0.92:
        slot = slots["uav_info"]
        return encode_frame(
            slot.topic_id, slot.codec.encode(slot.codec.new(motor_num=4, uav_model=UAV_HYDRUS))
        )
    if kind < 0.96:
        frame = bytearray(encode_frame(slots["desire_coordinate"].topic_id, bytes(12)))
        frame[-1] ^= 0x5A  # a bad checksum
        return bytes(frame)
    return rng.randbytes(rng.randrange(1, 6))


@pytest.mark.parametrize("seed", range(3))
def test_command_runs_and_message_handlers_give_the_golden_run(
    seed: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    rng = random.Random(seed)
    taken = [0, 0]  # frames the runs applied, runs that stopped early
    inner = sm_commands._apply_commands

    def counting(items: list, *args: Any) -> tuple[int, Any]:
        n, exc = inner(items, *args)
        taken[0] += n
        taken[1] += n < len(items)
        return n, exc

    monkeypatch.setattr(sm_commands, "_apply_commands", counting)
    mirrors = [_mirror(True), _mirror(False)]
    try:
        for m, pc in mirrors:
            pc.write(encode_frame(C.TopicId.PUBLISHER, b""))
            m.tick(0.0)
            assert m.session.configured
            m.core.set_uav_info(4, UAV_HYDRUS)
            m.core.set_pwm_info_hydrus_example()
        runs, messages = (m for m, _ in mirrors)
        assert runs.session.command_run is not None and messages.session.command_run is None
        slots = {s.name: s for s in runs.session.subscribers}
        held = b""
        ticks: list[list[str]] = [[], []]  # per mirror: what each tick left, as text
        for k in range(1, 500):
            now = k * 0.001
            data = held + b"".join(_piece(rng, slots) for _ in range(rng.randrange(5)))
            cut = len(data) if rng.random() < 0.8 else rng.randrange(len(data) + 1)
            data, held = data[:cut], data[cut:]  # a frame split across ticks now and then
            for (m, pc), seen in zip(mirrors, ticks, strict=True):
                pc.write(data)
                m.tick(now)
                out = m.last_output
                seen.append(
                    repr(
                        (
                            pc.read_available(),
                            m.diagnostics(),
                            m.core.target_angles.tolist(),
                            m.core.base_thrust.tolist(),
                            None if out is None else out.duty.tolist(),
                        )
                    )
                )
        for seen in ticks:  # the command runs, then the message handlers: the same run
            windows = {
                f"{start:03d}": golden_digests.sha("\n".join(seen[start : start + 50]).encode())
                for start in range(0, len(seen), 50)
            }
            golden_digests.check("spinal_commands.json", f"seed {seed}", windows)
        counters = runs.counters
        assert counters.received["four_axes/command"] > 20
        assert sum(counters.received.values()) > 250
        assert sum(counters.rejected.values()) > 50 and len(counters.rejected) >= 3
        assert taken[0] > 80 and taken[1] > 50, taken  # runs taken, and stopped early
    finally:
        for m, _ in mirrors:
            m.close()


def _goals(master: Any) -> list[int]:
    return [view.goal_position for view in master.servo_states.values()]


def _stack(base: str):
    from rdm.scenarios.common import sim_stack_options
    from rdm.scenarios.hover import HOVER_Z, make_script
    from rdm.scenarios.stack import build_stack

    opts = sim_stack_options(0, "inproc", speed=None)
    return build_stack("commands", base, opts, make_script(np.array([0.483, 0.0, HOVER_Z])))


def test_servo_targets_follow_the_topic_rules_on_a_running_master() -> None:
    """Random index/angle lists, bad ones included, against the ``servo/target_states`` rules
    written out (``_expected_targets``): a frame the call applies sets exactly the goals of
    the rules; one the rules refuse is declined with nothing changed (the bridge then
    rejects it). Catches a repeated index keeping its first value instead of its last."""
    rng = random.Random(5)
    codec = REG.msg("spinal/ServoControlCmd")
    with tempfile.TemporaryDirectory() as base:
        stack = _stack(base)
        try:
            stack.loop.run_ticks(2600)  # past the CAN boot: the master runs
            spinal = stack.spinal
            master = spinal.master
            core = spinal.servos.command_core()
            assert core is master.core
            slot = next(s for s in spinal.session.subscribers if s.name == "servo/target_states")
            keys = master.servo_keys()
            n = len(keys)
            applied = declined = 0
            for case in range(500):
                k = rng.choice([0, 1, 3, n, n + 2])
                index = [rng.choice([0, 1, n - 1, rng.randrange(n)]) for _ in range(k)]
                angles = [rng.randint(-3000, 3000) for _ in range(k)]
                if case % 7 == 0 and k:
                    index[rng.randrange(k)] = rng.choice([n, 255])
                if case % 11 == 0 and k:
                    angles[rng.randrange(k)] = rng.choice([1 << 14, -(1 << 14) - 1, 32767])
                if case % 13 == 0:
                    angles = angles[:-1] if angles else [5]
                payload = codec.encode(codec.new(index=index, angles=angles))
                start = [rng.randint(-2000, 2000) for _ in range(n)]
                master.core.set_servo_target_list(
                    [(s, i, g) for (s, i), g in zip(keys, start, strict=True)]
                )
                got, exc = _rdm.spinal_apply_commands(
                    [(slot.topic_id, payload, 0)],
                    spinal._command_kinds,
                    C.FIRST_USER_TOPIC_ID,
                    spinal.core,
                    core,
                    0.0,
                )
                assert exc is None
                outcome, goals = _expected_targets(keys, start, index, angles)
                if got == 1:
                    assert (outcome, _goals(master)) == ("ok", goals), (index, angles)
                    applied += 1
                else:
                    assert got == 0 and _goals(master) == start, (index, angles)
                    declined += outcome != "ok"
            assert applied > 200 and declined > 100
            # a master that is not the mirror's one-call core: servo frames are declined
            got, exc = _rdm.spinal_apply_commands(
                [(slot.topic_id, payload, 0)],
                spinal._command_kinds,
                C.FIRST_USER_TOPIC_ID,
                spinal.core,
                None,
                0.0,
            )
            assert (got, exc) == (0, None)
        finally:
            stack.close()


def test_declines_what_it_does_not_take() -> None:
    mirror, _pc = _mirror(True)
    try:
        kinds = mirror._command_kinds
        first = C.FIRST_USER_TOPIC_ID
        slots = {s.name: s for s in mirror.session.subscribers}
        desire = slots["desire_coordinate"]
        coord = REG.msg("spinal/DesireCoord")
        good = (desire.topic_id, coord.encode(coord.new(roll=0.1, pitch=0.2, yaw=0.3)), 0)
        core = mirror.core
        # applied, in order, up to the first item it does not take
        other = (slots["uav_info"].topic_id, bytes(2), 0)
        run = [good, good, other, good]
        assert _rdm.spinal_apply_commands(run, kinds, first, core, None, 0.0) == (2, None)
        for item in (
            (C.TopicId.TIME, bytes(8), 0),  # a reserved id
            (first + len(kinds) + 3, bytes(12), 0),  # no such subscriber
            (desire.topic_id, bytearray(12), 0),  # not bytes
            (desire.topic_id, bytes(12)),  # not a parser item
            [desire.topic_id, bytes(12), 0],
            "frame",
        ):
            assert _rdm.spinal_apply_commands([item], kinds, first, core, None, 0.0) == (0, None)
        assert _rdm.spinal_apply_commands([], kinds, first, core, None, 0.0) == (0, None)
        # a rejection comes back as the core's own exception, the item counted as done
        gains = slots["rpy/gain"]
        term = REG.msg("spinal/RollPitchYawTerm")
        three = REG.msg("spinal/RollPitchYawTerms").encode(
            REG.msg("spinal/RollPitchYawTerms").new(
                motors=[term.new(**{f.name: 1 for f in term.spec.fields})] * 3
            )
        )
        core.set_uav_info(4, UAV_HYDRUS)
        n, exc = _rdm.spinal_apply_commands(
            [good, (gains.topic_id, three, 0), good], kinds, first, core, None, 0.0
        )
        assert n == 1 and isinstance(exc, _rdm.RdmError)
        with pytest.raises(type(exc), match=str(exc)):
            core.set_gains_wire_rows([[1] * 7] * 3)
    finally:
        mirror.close()
