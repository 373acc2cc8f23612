"""Which Neuron carries which servo: the default CAN wiring rule of a multilink robot.

Pure data (no MuJoCo, no I/O), so the onboard node can number servos the way Spinal does
without loading the simulator, and the plant bridge can wire the Neuron mirrors the same way.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

#: Servos one Neuron drives in the default wiring.
MAX_SERVOS_PER_NEURON = 4
#: Slave ids available on one Spinal CAN bus.
MAX_NEURONS = 14


def default_neuron_joints(
    rotor_names: Sequence[str],
    vectoring_units: Sequence[Mapping],
    joint_order: Sequence[str],
) -> dict[int, tuple[str, tuple[str, ...]]]:
    """``{slave: (rotor, joints)}`` of the default wiring (the RDM's, documented):

    * one Neuron per rotor (Spinal counts one motor per Neuron), slave ids 1.. in rotor order;
    * each vectoring unit's roll and pitch servos sit on the Neuron of the unit's first rotor;
    * the link joints (the rest of ``joint_order``, in order) are split evenly, contiguously,
      over the Neurons that carry no vectoring servo, in slave order (RDM: q1-q3 on Neuron 2,
      q4-q6 on Neuron 4); what does not fit goes to the spare slots of the others.
    """
    rotor_slave = {name: i + 1 for i, name in enumerate(rotor_names)}
    if len(rotor_slave) > MAX_NEURONS:
        raise ValueError(f"default_layout: {len(rotor_slave)} rotors > {MAX_NEURONS} Neurons")
    joints: dict[int, list[str]] = {s: [] for s in rotor_slave.values()}
    vectoring: set[str] = set()
    for unit in vectoring_units:
        rotors = unit.get("rotors", [])
        if not rotors or rotors[0] not in rotor_slave:
            raise ValueError(f"default_layout: vectoring unit {unit.get('name')!r} has no rotor")
        for key in ("roll_joint", "pitch_joint"):
            if key in unit:
                joints[rotor_slave[rotors[0]]].append(unit[key])
                vectoring.add(unit[key])
    links = [j for j in joint_order if j not in vectoring]
    free = [s for s, js in joints.items() if not js] or list(joints)
    at = 0
    for i, slave in enumerate(free):
        share = math.ceil((len(links) - at) / (len(free) - i))
        take = min(share, MAX_SERVOS_PER_NEURON - len(joints[slave]))
        joints[slave].extend(links[at : at + take])
        at += take
    for slave in joints:  # spill-over into spare slots
        while at < len(links) and len(joints[slave]) < MAX_SERVOS_PER_NEURON:
            joints[slave].append(links[at])
            at += 1
    if at < len(links):
        raise ValueError(f"default_layout: {len(links) - at} joints do not fit on the Neurons")
    return {slave: (rotor, tuple(joints[slave])) for rotor, slave in rotor_slave.items()}


def can_table(neuron_joints: Mapping[int, tuple[str, Sequence[str]]]) -> list[str]:
    """Spinal's servo numbering: Neurons by slave id, then servo index on each Neuron."""
    return [j for slave in sorted(neuron_joints) for j in neuron_joints[slave][1]]
