"""The onboard PC as another process: what the simulated robot holds in the onboard node's
place when ``rdm onboard`` runs on its own (``StackOptions.uart = "external"``).

The robot's side offers the Spinal and foot-sensor UARTs as pty slaves (:attr:`uart_path`,
:attr:`foot_path`) for ``rdm onboard`` to open, and sends it motion capture as a real system
does: signed ``pose`` datagrams of the ground link (:mod:`rdm.ground`) to its control port,
once :meth:`attach` gave it a client. Nothing here reads the node's UARTs.
"""

from __future__ import annotations

from collections import Counter
from typing import Any

from rdm.nodes.onboard_config import OnboardConfig


class ExternalOnboard:
    """Stands where the in-process :class:`rdm.nodes.onboard.OnboardNode` would."""

    name = "onboard"

    def __init__(self, config: OnboardConfig, uart_path: str, foot_path: str) -> None:
        self.config = config
        self.uart_path = uart_path
        self.foot_path = foot_path
        self.client: Any = None
        self.counts: Counter[str] = Counter()

    def attach(self, client: Any) -> None:
        """The ground client (:class:`rdm.ground.client.GroundClient`) poses go out on."""
        self.client = client

    def set_mocap_pose(
        self, position: list[float], quaternion: list[float], stamp: float | None = None
    ) -> bool:
        """One marker pose to the node's control port (sent now; the node stamps it on
        arrival). Before :meth:`attach` the pose is counted and dropped."""
        if self.client is None:
            self.counts["pose_unattached"] += 1
            return False
        _, data = self.client.datagram("pose", {"position": position, "quaternion": quaternion})
        try:
            self.client.send(data)
        except OSError:
            self.counts["pose_send_error"] += 1
            return False
        self.counts["pose_sent"] += 1
        return True

    def close(self) -> None:
        """Nothing of its own to close (the ptys belong to the stack)."""
