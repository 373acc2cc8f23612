"""The Spinal mirror's battery sampling and control steps: the low-passed battery reading,
the :class:`rdm._rdm.SpinalStep` steps at ``rate_hz`` with their events (acks, fail-safes,
guards) and the duty list for the CAN master.

:class:`SpinalControl` is a part of :class:`rdm.nodes.spinal_mirror.SpinalMirror`: its methods
read the mirror's state (``core``, ``master``, ``counters``, ``pwm_test`` ...).
"""

from __future__ import annotations

from typing import Any

from rdm._rdm import spinal_duty_list as _duty_list
from rdm.control.attitude import MAX_ROTORS
from rdm.nodes.can_master import IDLE_DUTY
from rdm.protocol.rosserial import constants as C

#: Control steps replayed at most per tick when the loop runs late; then re-phased.
MAX_CONTROL_CATCH_UP = 5

_FAILSAFE_TEXT = {
    "failsafe_timeout": "failsafe: cannot connect with ROS",
    "failsafe_tilt": "failsafe: the roll pitch angles are too large",
    "failsafe_command_tilt": "failsafe: target angles are too large",
}
#: The controller's guards (docs/spinal.md "Guards on the actuator path"): the first of a run
#: is logged as a warning; every trip is counted by the core (``core.counters``).
_GUARD_TEXT = {
    "voltage_rejected": "guard: implausible battery voltage, the last good one is used",
    "command_saturated": "guard: four_axes/command thrust saturated",
    "non_finite_output": "guard: non-finite thrust, every motor at min duty",
    "alpha_bounded": "guard: saturation factor alpha below -1, bounded to -1",
}


class SpinalControl:
    """The battery and control steps of :class:`rdm.nodes.spinal_mirror.SpinalMirror` (a
    part of it)."""

    def _battery(self, now_ms: int) -> None:
        """The battery task (every 20 ms, ``SpinalMirrorState.battery_sample``: the low-pass
        ``v = 0.99 v + 0.01 sample``); a non-finite sample is counted and the voltage kept."""
        self._last_pub["_battery_sample"] = now_ms
        if not self._state.battery_sample(now_ms):
            self.counters.rejected["battery_non_finite"] += 1

    def _control(self, now: float) -> None:
        period = 1.0 / self.rate_hz
        state = self._state
        if state.next_control is None:
            state.next_control = now
        steps = 0
        while now >= state.next_control - 1e-9:
            if steps == MAX_CONTROL_CATCH_UP:
                self.counters.control_overruns += 1
                state.next_control = now + period
                break
            self._step(now)
            steps += 1
            state.next_control += period

    def _step(self, now: float) -> None:
        state = self._state
        out = self.core.step(now, state.gyro, state.acc, state.mag, state.step_voltage())
        self.last_output = out  # the core counts the step (counters.control_steps)
        if self.pwm_test is None:
            # No event and the controller's own duties: the list _step_tail builds, from
            # the core's output in one call (None: an event or another case, below).
            n = self.master.motor_number
            if n == self.core.motor_number:
                duties = _duty_list(out, n, IDLE_DUTY)
                if duties is not None:
                    self.duties = duties
                    return
        self._step_tail(out)

    def _step_tail(self, out: Any) -> None:
        """The events of a control step, then the duty list for the CAN master."""
        for kind, value in out.events:
            if kind == "ack":
                self.counters.acks[int(value)] += 1
                self._publish_topic("flight_config_ack", self._msg.uint8.new(data=int(value)))
            elif kind == "rejected":
                self._log(C.LogLevel.ERROR, str(value))
            elif kind in _FAILSAFE_TEXT:
                self.counters.failsafes[kind] += 1
                self._log(C.LogLevel.ERROR, _FAILSAFE_TEXT[kind])
            elif kind in _GUARD_TEXT:
                self._log(C.LogLevel.WARN, _GUARD_TEXT[kind])
            elif kind == "events_dropped":
                self.counters.failsafes["events_dropped"] += int(value)
        n = self.master.motor_number
        if self.pwm_test is not None:
            duties = (self.pwm_test + [IDLE_DUTY] * n)[:n]
        elif n and n == self.core.motor_number and n <= MAX_ROTORS:
            # tolist: the same Python floats as float() of each element, in one call
            duties = [min(1.0, max(IDLE_DUTY, d)) for d in out.duty.tolist()[:n]]
        else:
            duties = [IDLE_DUTY] * n
        self.duties = duties
