"""Servo topics of the Spinal mirror <-> the CAN master's servo table (``spine.cpp`` role).

Index convention (**assumed**, the fact sheet does not give it): a servo's ``index`` in
``servo/target_states``, ``servo/target_current``, ``servo/torque_enable``, ``servo/states``
and ``servo/torque_states`` is its position in the CAN master's table, Neurons sorted by slave
id, servos by their index on the Neuron (``CanMaster.servo_states`` order). ``servo/states``
carries the servos with send_data_flag; ``servo/torque_states`` carries every servo.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from rdm import _rdm
from rdm.nodes.can_master import CanMaster, MasterState, ServoEntryView
from rdm.protocol.neuron.servo import WORD_VALUE_MAX, WORD_VALUE_MIN
from rdm.protocol.rosserial.codec import RosTime

#: The whole ServoStates frame from the master's table in one core call.
_states_frame = _rdm.spinal_servo_states_frame


class MirrorRejection(ValueError):
    """A command the mirror itself refuses (servo topics, pwm_test); ``reason`` is the counter
    key in ``MirrorCounters.rejected``."""

    def __init__(self, reason: str, text: str) -> None:
        super().__init__(text)
        self.reason = reason


#: The generated layout of ``spinal/ServoStates`` that ``rdm._rdm.spinal_servo_states_frame``
#: packs: ``time stamp`` then ``ServoState[] servos`` (index, angle, temp, load, error) inline.
_SERVO_STATES_SIGNATURE = (
    ("fixed", (("stamp", "t", None),), "II"),
    ("nested", "servos", "BhBhB", ("index", "angle", "temp", "load", "error")),
)


def _is_servo_states_layout(codec: Any) -> bool:
    """Whether ``codec`` packs ``spinal/ServoStates`` as ``rdm._rdm.spinal_servo_states_frame``
    does (its generated layout's signature)."""
    return codec.layout.signature() == _SERVO_STATES_SIGNATURE


def target_rejection(exc: ValueError) -> MirrorRejection:
    """The rejection of a ``servo/target_states`` whose goals the master core refused."""
    return MirrorRejection("servo_value", f"servo/target_states: {exc}")


class ServoBridge:
    """Applies servo commands from the UART to a :class:`CanMaster`; builds servo reports.

    The master's table is read in one core call (``servo_keys()``, ``servo_reports()``);
    the ``servo/states`` frame is built from it in one call
    (``rdm._rdm.spinal_servo_states_frame``) when the codec has the standard layout.
    """

    def __init__(self, master: CanMaster) -> None:
        self.master = master
        #: The last ``spinal/ServoState`` built per servo with its field values; reused while
        #: the values repeat (a message is only encoded, never changed).
        self._state_msgs: list[tuple[tuple, Any]] = []
        self._state_codec: Any = None  # the codec those messages come from
        #: states_frame: the ServoStates codec whose layout was checked
        self._payload_codec: Any = None
        self._frame_core = master.core

    def table(self) -> list[tuple[tuple[int, int], ServoEntryView]]:
        """Every servo in index order (empty until the master runs)."""
        if self.master.state is not MasterState.RUNNING:
            return []
        return list(self.master.servo_states.items())

    def _resolve(self, topic: str, index: Sequence[int], values: Sequence[int]):
        if len(index) != len(values):
            raise MirrorRejection(
                "wrong_length", f"{topic}: {len(index)} indices but {len(values)} values"
            )
        keys = self._keys()
        if not keys:
            raise MirrorRejection("servo_not_ready", f"{topic}: no servo enumerated on CAN")
        out = []
        for i, value in zip(index, values, strict=True):
            if not 0 <= i < len(keys):
                raise MirrorRejection(
                    "servo_index", f"{topic}: servo index {i} not in 0..{len(keys) - 1}"
                )
            out.append((keys[i], int(value)))
        return out

    def _keys(self) -> list[tuple[int, int]]:
        """``(slave, index)`` of every servo in index order (empty until the master runs)."""
        if self.master.state is not MasterState.RUNNING:
            return []
        return self.master.servo_keys()

    def _reports(self) -> list[tuple[bool, int, int, int, int, bool]]:
        """``(send_data_flag, angle, temperature, current, error, torque_enable)`` of every
        servo in index order (the core's table holds i16 / u8 values: each fits its message
        field; empty until running)."""
        if self.master.state is not MasterState.RUNNING:
            return []
        return self.master.servo_reports()

    def target_states(self, msg: Any) -> None:
        """``servo/target_states`` (``spinal/ServoControlCmd``): goal positions, raw ticks."""
        self.target_states_values(msg.index, msg.angles)

    def target_states_values(self, index: Sequence[int], angles: Sequence[int]) -> None:
        """:meth:`target_states` of a message's ``index`` and ``angles`` fields: every pair
        checked (lengths, servo index, 15-bit value; a :class:`MirrorRejection` names the
        first bad one, nothing applied), then the goals in index order in one core call (a
        repeated index leaves its last value), as ``rdm._rdm.spinal_apply_commands`` sets
        them."""
        targets = []
        for (slave, idx), value in self._resolve("servo/target_states", index, angles):
            if not WORD_VALUE_MIN <= value <= WORD_VALUE_MAX:
                raise MirrorRejection(
                    "servo_value",
                    f"servo/target_states: servo ({slave}, {idx}) target {value} not a 15-bit int",
                )
            targets.append((slave, idx, value))
        try:
            self._frame_core.set_servo_target_list(targets)
        except ValueError as exc:  # the core's own refusal
            raise target_rejection(exc) from exc

    def command_core(self) -> Any | None:
        """The master's core while it runs, else None: for ``rdm._rdm.spinal_apply_commands``,
        which then sets the goals as :meth:`target_states_values` does."""
        return self._frame_core if self.master.state is MasterState.RUNNING else None

    def target_current(self, msg: Any) -> None:
        """``servo/target_current``: the ``angles`` field carries the goal current."""
        pairs = self._resolve("servo/target_current", msg.index, msg.angles)
        for (slave, idx), value in pairs:
            try:
                self.master.set_servo_current(slave, idx, value)
            except ValueError as exc:
                raise MirrorRejection("servo_value", f"servo/target_current: {exc}") from exc

    def torque_enable(self, msg: Any) -> None:
        """``servo/torque_enable`` (``spinal/ServoTorqueCmd``)."""
        pairs = self._resolve("servo/torque_enable", msg.index, msg.torque_enable)
        for (slave, idx), value in pairs:
            self.master.set_servo_torque(slave, idx, bool(value))

    def states(self, codec: Any, stamp: Any) -> Any | None:
        """A ``spinal/ServoStates`` of the servos with send_data_flag, or None if there are none."""
        if codec.servo_state is not self._state_codec:
            self._state_codec, self._state_msgs = codec.servo_state, []
        servos = self._states_reused(codec.servo_state.new)
        if not servos:
            return None
        return codec.servo_states.new(stamp=stamp, servos=servos)

    def states_frame(self, codec: Any, stamp: Any, topic_id: int) -> bytes | bool | None:
        """``encode_frame(topic_id, codec.encode(self.states(..., stamp)))``: the whole frame
        from the master's servo table in one call (``rdm._rdm.spinal_servo_states_frame``).
        None when no servo has send_data_flag, False when this path does not apply (another
        layout, a stamp that is not a :class:`RosTime`: then build the message with
        :meth:`states`)."""
        core = self._frame_core
        if stamp.__class__ is not RosTime:
            return False
        if codec is not self._payload_codec:
            if not _is_servo_states_layout(codec):
                return False
            self._payload_codec = codec
        if self.master.state is not MasterState.RUNNING:
            return None  # no servo reported: no message
        return _states_frame(topic_id, stamp[0], stamp[1], core)

    def kernel_frame_core(self, codec: Any) -> Any:
        """The master's core when :meth:`states_frame` of ``codec`` with a ``RosTime``
        stamp is exactly ``rdm._rdm.spinal_servo_states_frame(topic_id, sec, nsec, core)``
        while the master runs (the lockstep kernel then builds that frame itself); None
        otherwise (also before the codec's first frame, whose layout check this skips)."""
        return self._frame_core if codec is self._payload_codec else None

    def _states_reused(self, new: Any) -> list[Any]:
        """The ``servos`` list of :meth:`states`, reusing each servo's last message while its
        values are unchanged (same fields, same bytes; fewer objects built at 50 Hz)."""
        cache = self._state_msgs
        out = []
        for i, (send, angle, temp, load, error, _torque) in enumerate(self._reports()):
            if not send:
                continue
            values = (i, angle, temp, load, error)
            if i < len(cache):
                kept, msg = cache[i]
                if kept != values:
                    msg = new(index=i, angle=angle, temp=temp, load=load, error=error)
                    cache[i] = (values, msg)
            else:
                msg = new(index=i, angle=angle, temp=temp, load=load, error=error)
                cache.extend([((), None)] * (i - len(cache)))
                cache.append((values, msg))
            out.append(msg)
        return out

    def torque_states(self, codec: Any) -> Any | None:
        """A ``spinal/ServoTorqueStates`` of every servo, or None if there are none."""
        reports = self._reports()
        if not reports:
            return None
        return codec.torque_states.new(torque_enable=[int(r[5]) for r in reports])
