"""The ground link: authenticated commands from the ground station (``rdm ctl``) to the
onboard node (``rdm onboard --control``), acknowledged, with a heartbeat.

* :mod:`rdm.ground.message`: the datagram format, bounded size and depth, typed reasons;
* :mod:`rdm.ground.auth`: the key file, HMAC-SHA256 signatures, replay protection;
* :mod:`rdm.ground.commands`: the command table (arguments, rules, node methods);
* :mod:`rdm.ground.ee`: end-effector targets planned with :mod:`rdm.planner`;
* :mod:`rdm.ground.heartbeat`: ground-station loss and restore;
* :mod:`rdm.ground.port`: the onboard node (:class:`GroundPort`);
* :mod:`rdm.ground.client`: the ground-station end (:class:`GroundClient`).

docs/flying.md ("The ground link") describes the protocol for operators.
"""

from rdm.ground.auth import KeyFileError, Verifier, load_key, sign, write_key
from rdm.ground.client import AckTimeout, GroundClient
from rdm.ground.message import Reason, Rejected
from rdm.ground.port import GroundLinkConfig, GroundPort

__all__ = [
    "AckTimeout",
    "GroundClient",
    "GroundLinkConfig",
    "GroundPort",
    "KeyFileError",
    "Reason",
    "Rejected",
    "Verifier",
    "load_key",
    "sign",
    "write_key",
]
