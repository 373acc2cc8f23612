"""OnboardNode against the Spinal core (rdm.control.attitude.AttitudeController, the firmware
mirror's state machine and control law) behind a rosserial ClientSession over a pty pair: every
message the node sends is applied in its wire form, acks come from the core. Arming completes
and the PWM duty follows the commanded base thrust (numpy SQRT curve of fact sheet 3.6)."""

from __future__ import annotations

import numpy as np
import pytest
from onboard_rig import Rig, SpinalCore

from rdm.model import Robot
from rdm.nodes.onboard import OnboardNode
from rdm.nodes.onboard_config import OnboardConfig

pytestmark = pytest.mark.timeout(300)
ROBOT = Robot.default()


def sqrt_duty(f: np.ndarray) -> np.ndarray:
    """Hydrus example at its 25.2 V reference (v_factor 1): pwm% from the SQRT curve."""
    p0, p1, p2 = 12.3593793002, -6.627443098, 0.07983707
    x = (-p1 + np.sqrt(p1 * p1 - 40 * p2 * (p0 - f))) / (2 * p2)
    return np.clip(x / 100, 0.59, 0.9375)


def test_arming_and_pwm_follow_base_thrust_through_spinal_core() -> None:
    rig = Rig(lambda u, f: OnboardNode(u, f, ROBOT, config=OnboardConfig()))
    try:
        rig.auto_ack = False
        spinal = SpinalCore(rig)
        rig.on_message, rig.after_spin = spinal.on_message, spinal.after_spin
        rig.servo_q = np.array([0.1, -0.1, 0.1, 0.2, 0.05, 0.0, 0.0, 0.0, 0.0, 0.0])
        t = rig.run(0.0, 0.3)
        assert spinal.rejected == 0 and not spinal.core.armed
        rig.node.set_target([0.0, 0.0, 1.0], 0.0)
        rig.node.arm()
        z = {"v": 1.0}

        def each(_t):
            rig.node.set_mocap([0.0, 0.0, z["v"]], [0.0, 0.0, 0.0], 0.0)

        t = rig.run(t, t + 0.5, each=each)
        assert spinal.core.armed and rig.node.state.value == "armed"
        assert spinal.rejected == 0
        duties = []
        for z_now in (1.0, 0.9, 1.1):  # below the target -> more thrust, above -> less
            z["v"] = z_now
            t = rig.run(t, t + 0.1, each=each)
            base = np.array(rig.by_topic["four_axes/command"][-1][1].base_thrust, dtype=float)
            assert np.allclose(spinal.core.base_thrust, base, rtol=1e-6)
            out = spinal.last_output
            # level, at rest, zero attitude targets: thrust = base (no rp, no yaw term)
            assert np.allclose(out.thrust, base, atol=1e-4)
            assert np.allclose(out.duty, sqrt_duty(base), atol=1e-6)
            duties.append(np.array(out.duty))
        assert np.all(duties[1] > duties[0]) and np.all(duties[2] < duties[0])
        assert spinal.core.counters["failsafes"] == 0
    finally:
        rig.close()
