"""Build the shipped robot descriptions (URDF + TOML) from one parts list.

The RDM of Nishio et al. and its RCM comparison robot (Sec. II-A-3) are made of the same
parts; only where the two dual-rotor vectoring apparatuses sit differs. This module holds
the parts list once (Table IV plus the ASSUMPTIONS documented in ``docs/model.md``) and
writes both files, so the shipped ``rdm.urdf``/``rdm.toml`` and ``rcm.urdf``/``rcm.toml`` are
generated, never hand-edited (``tests/test_model_description.py`` checks they match), and
the Table II variants (arm vectoring apparatus at the root/middle/end of the middle link)
are one call: ``build_description("rdm", arm_unit_position=0.5)``.

Joint order everywhere: ``q = [q1, q2, q3, q4, q5, q6, alpha1, beta1, alpha2, beta2]``;
rotors 1, 2 sit on the foot unit (alpha1, beta1), rotors 3, 4 on the arm unit.

Regenerate the shipped files with ``python -m rdm.descriptions``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

# --- Table IV (paper) --------------------------------------------------------------------
ROOT_LINK_LENGTH = 0.40
MIDDLE_LINK_LENGTH = 0.40
END_LINK_LENGTH = 0.25
ROOT_LINK_MASS = 1.12  # includes the foot vectoring apparatus (ASSUMPTION, see below)
MIDDLE_LINK_MASS = 1.21  # includes the arm vectoring apparatus (ASSUMPTION)
END_LINK_MASS = 0.19
JOINT_MODULE_MASS = 0.13  # one per link joint q2..q6 (ASSUMPTION: five modules)
PROCESSOR_MASS = 0.15
TOTAL_LINK_MASS = 3.35
FOOT_MODULE_MASS = 0.35  # foot plate, wrench sensor and the q1 servo
FOOT_PLATE_SIZE = (0.10, 0.15)  # x, y [m]; Table VII H_x, H_y = 0.04, 0.07 fit inside

# --- ASSUMPTIONS (not in the paper) --------------------------------------------------------
# A vectoring apparatus: roll stage (ring around the link, XH430 roll servo, timing belt)
# and pitch stage (XL430 pitch servo, two COBRA-2217 motors with 127 mm props, ESCs, frame).
UNIT_ROLL_STAGE_MASS = 0.12
UNIT_PITCH_STAGE_MASS = 0.33
# Table IV lists 1.12 + 1.21 + 0.19 + 5 x 0.13 + 0.15 = 3.32 kg against a 3.35 kg total; the
# 0.03 kg remainder is modelled as a wiring harness at the middle of the root link.
HARNESS_MASS = round(
    TOTAL_LINK_MASS
    - (ROOT_LINK_MASS + MIDDLE_LINK_MASS + END_LINK_MASS + 5 * JOINT_MODULE_MASS + PROCESSOR_MASS),
    6,
)
ROOT_LINK_RADIUS = 0.02
MIDDLE_LINK_RADIUS = 0.02
END_LINK_RADIUS = 0.015
Q1_AXIS_BELOW_PLATE = 0.05  # q1 axis sits this far below the plate's contact face
FOOT_MODULE_COG = (0.0, 0.0, -0.03)
FOOT_MODULE_BOX = (0.10, 0.15, 0.06)
JOINT_MODULE_BOX = (0.05, 0.05, 0.05)
PROCESSOR_BOX = (0.10, 0.06, 0.03)
ROTOR_SPACING = 0.14  # centre distance of the two rotors of a unit (> 127 mm diameter)
ROTOR_HEIGHT = 0.03  # rotor plane above the unit's pitch axis
ROTOR_DIAMETER = 0.127
DRAG_TO_THRUST = 0.016  # c of eq. (9): rotor drag torque per thrust [N m / N]
THRUST_MIN = 1.0
THRUST_MAX = 20.0
LINK_STALL_TORQUE = 3.4  # XH430-W350-R
PITCH_STALL_TORQUE = 1.5  # XL430-W250-T
HALF_PI = math.pi / 2

JOINT_ORDER = ("q1", "q2", "q3", "q4", "q5", "q6", "alpha1", "beta1", "alpha2", "beta2")


@dataclass(frozen=True)
class Description:
    """A generated robot description: URDF text and TOML text (which names the URDF)."""

    name: str
    urdf: str
    toml: str

    def write(self, directory: Path) -> tuple[Path, Path]:
        """Write ``<name>.urdf`` and ``<name>.toml`` into ``directory``; return both paths."""
        directory.mkdir(parents=True, exist_ok=True)
        urdf_path = directory / f"{self.name}.urdf"
        toml_path = directory / f"{self.name}.toml"
        urdf_path.write_text(self.urdf)
        toml_path.write_text(self.toml)
        return urdf_path, toml_path


# --- inertia helpers -----------------------------------------------------------------------
def _cylinder_x(mass: float, radius: float, length: float) -> tuple[float, float, float]:
    """Principal inertia of a solid cylinder whose axis is x."""
    ixx = mass * radius**2 / 2
    iyy = mass * (3 * radius**2 + length**2) / 12
    return ixx, iyy, iyy


def _box(mass: float, size: tuple[float, float, float]) -> tuple[float, float, float]:
    x, y, z = size
    return mass * (y * y + z * z) / 12, mass * (x * x + z * z) / 12, mass * (x * x + y * y) / 12


@dataclass(frozen=True)
class _Part:
    """A rigid part: mass, centre of mass in its link frame, principal inertia (link axes)."""

    name: str
    mass: float
    com: tuple[float, float, float]
    inertia: tuple[float, float, float]


def _combine(parts: list[_Part]) -> tuple[float, tuple[float, ...], tuple[float, ...]]:
    """Total mass, CoG and full inertia tensor about the CoG (ixx, ixy, ixz, iyy, iyz, izz)."""
    mass = sum(p.mass for p in parts)
    com = tuple(sum(p.mass * p.com[k] for p in parts) / mass for k in range(3))
    t = [[0.0] * 3 for _ in range(3)]
    for p in parts:
        d = [p.com[k] - com[k] for k in range(3)]
        dd = sum(x * x for x in d)
        for i in range(3):
            for j in range(3):
                t[i][j] += (p.inertia[i] if i == j else 0.0) + p.mass * (
                    (dd if i == j else 0.0) - d[i] * d[j]
                )
    return mass, com, (t[0][0], t[0][1], t[0][2], t[1][1], t[1][2], t[2][2])


def _f(x: float) -> str:
    """Format a number compactly and exactly enough (12 significant digits)."""
    s = f"{x:.12g}"
    return "0" if s == "-0" else s


def _vec(v: tuple[float, ...]) -> str:
    return " ".join(_f(x) for x in v)


def _inertial(parts: list[_Part]) -> str:
    mass, com, i = _combine(parts)
    names = ", ".join(f"{p.name} {_f(p.mass)} kg" for p in parts)
    return (
        f"    <!-- {names} -->\n"
        f"    <inertial>\n"
        f'      <origin xyz="{_vec(com)}" rpy="0 0 0"/>\n'
        f'      <mass value="{_f(mass)}"/>\n'
        f'      <inertia ixx="{_f(i[0])}" ixy="{_f(i[1])}" ixz="{_f(i[2])}" '
        f'iyy="{_f(i[3])}" iyz="{_f(i[4])}" izz="{_f(i[5])}"/>\n'
        f"    </inertial>\n"
    )


def _cylinder_geom(radius: float, length: float, x0: float) -> str:
    """A cylinder along +x starting at x0 (URDF cylinders are along z, so rotate by pitch)."""
    origin = f'<origin xyz="{_f(x0 + length / 2)} 0 0" rpy="0 {_f(HALF_PI)} 0"/>'
    geom = f'<geometry><cylinder radius="{_f(radius)}" length="{_f(length)}"/></geometry>'
    return f"    <collision>{origin}{geom}</collision>\n"


def _box_geom(size: tuple[float, float, float], center: tuple[float, float, float]) -> str:
    origin = f'<origin xyz="{_vec(center)}" rpy="0 0 0"/>'
    return f'    <collision>{origin}<geometry><box size="{_vec(size)}"/></geometry></collision>\n'


def _link(name: str, parts: list[_Part], geoms: str = "") -> str:
    body = _inertial(parts) if parts else ""
    return f'  <link name="{name}">\n{body}{geoms}  </link>\n'


def _joint(
    name: str,
    parent: str,
    child: str,
    xyz: tuple[float, float, float],
    axis: tuple[float, float, float] | None,
    limit: float = HALF_PI,
    effort: float = LINK_STALL_TORQUE,
) -> str:
    kind = "fixed" if axis is None else "revolute"
    lines = [
        f'  <joint name="{name}" type="{kind}">',
        f'    <parent link="{parent}"/>',
        f'    <child link="{child}"/>',
        f'    <origin xyz="{_vec(xyz)}" rpy="0 0 0"/>',
    ]
    if axis is not None:
        lines.append(f'    <axis xyz="{_vec(axis)}"/>')
        lines.append(
            f'    <limit lower="{_f(-limit)}" upper="{_f(limit)}" effort="{_f(effort)}" '
            f'velocity="6.0"/>'
        )
    lines.append("  </joint>")
    return "\n".join(lines) + "\n"


def _module(name: str, x: float) -> _Part:
    return _Part(name, JOINT_MODULE_MASS, (x, 0.0, 0.0), _box(JOINT_MODULE_MASS, JOINT_MODULE_BOX))


def _unit(prefix: str, parent: str, mount_x: float, roll: str, pitch: str) -> str:
    """A dual-rotor vectoring apparatus: roll (alpha, link x axis) then pitch (beta, y)."""
    ring = _Part(
        "roll stage",
        UNIT_ROLL_STAGE_MASS,
        (0.0, 0.0, 0.0),
        _cylinder_x(UNIT_ROLL_STAGE_MASS, 0.04, 0.04),
    )
    plate_size = (0.06, ROTOR_SPACING + 0.06, 0.04)
    stage = _Part(
        "pitch stage with two rotors",
        UNIT_PITCH_STAGE_MASS,
        (0.0, 0.0, ROTOR_HEIGHT / 2),
        _box(UNIT_PITCH_STAGE_MASS, plate_size),
    )
    disk = (
        f'    <collision><origin xyz="0 {{y}} {_f(ROTOR_HEIGHT)}" rpy="0 0 0"/>'
        f'<geometry><cylinder radius="{_f(ROTOR_DIAMETER / 2)}" length="0.01"/></geometry>'
        f"</collision>\n"
    )
    return (
        _joint(roll, parent, f"{prefix}_roll", (mount_x, 0.0, 0.0), (1.0, 0.0, 0.0), math.pi)
        + _link(f"{prefix}_roll", [ring])
        + _joint(
            pitch,
            f"{prefix}_roll",
            f"{prefix}_pitch",
            (0.0, 0.0, 0.0),
            (0.0, 1.0, 0.0),
            math.pi,
            PITCH_STALL_TORQUE,
        )
        + _link(
            f"{prefix}_pitch",
            [stage],
            disk.format(y=_f(ROTOR_SPACING / 2)) + disk.format(y=_f(-ROTOR_SPACING / 2)),
        )
    )


def _urdf(name: str, foot_mount: float, arm_parent: str, arm_mount: float) -> str:
    unit_mass = UNIT_ROLL_STAGE_MASS + UNIT_PITCH_STAGE_MASS
    root_structure = ROOT_LINK_MASS - unit_mass
    middle_structure = MIDDLE_LINK_MASS - unit_mass
    lr, lm, le = ROOT_LINK_LENGTH, MIDDLE_LINK_LENGTH, END_LINK_LENGTH
    foot = _Part(
        "foot module", FOOT_MODULE_MASS, FOOT_MODULE_COG, _box(FOOT_MODULE_MASS, FOOT_MODULE_BOX)
    )
    root_parts = [
        _Part(
            "root link structure",
            root_structure,
            (lr / 2, 0, 0),
            _cylinder_x(root_structure, ROOT_LINK_RADIUS, lr),
        ),
        _Part("processor", PROCESSOR_MASS, (lr, 0, 0), _box(PROCESSOR_MASS, PROCESSOR_BOX)),
        _Part("harness", HARNESS_MASS, (lr / 2, 0, 0), (0.0, 0.0, 0.0)),
        _module("q2 module", lr),
    ]
    middle_parts = [
        _Part(
            "middle link structure",
            middle_structure,
            (lm / 2, 0, 0),
            _cylinder_x(middle_structure, MIDDLE_LINK_RADIUS, lm),
        ),
        _module("q4 module", lm),
    ]
    plate_center = (0.0, 0.0, FOOT_MODULE_COG[2])
    # Emitted after its parent link so MuJoCo's joint order equals JOINT_ORDER.
    arm_unit = _unit("arm_unit", arm_parent, arm_mount, "alpha2", "beta2")
    out = [
        '<?xml version="1.0"?>\n',
        f"<!-- {name}: generated by rdm.descriptions (python -m rdm.descriptions); do not edit.\n",
        "     Joint order of q: q1 q2 q3 q4 q5 q6 alpha1 beta1 alpha2 beta2.\n",
        "     Every ASSUMPTION behind these numbers is listed in docs/model.md. -->\n",
        f'<robot name="{name}">\n',
        "  <!-- MuJoCo: keep fixed-joint bodies (frames) separate. -->\n",
        '  <mujoco><compiler discardvisual="false" fusestatic="false"/></mujoco>\n',
        _link(
            "foot", [foot], _box_geom((FOOT_PLATE_SIZE[0], FOOT_PLATE_SIZE[1], 0.06), plate_center)
        ),
        _joint("q1", "foot", "root_link", (0.0, 0.0, -Q1_AXIS_BELOW_PLATE), (0.0, 1.0, 0.0)),
        _link("root_link", root_parts, _cylinder_geom(ROOT_LINK_RADIUS, lr, 0.0)),
        _unit("foot_unit", "root_link", foot_mount, "alpha1", "beta1"),
        _joint("q2", "root_link", "q3_housing", (lr, 0.0, 0.0), (0.0, 1.0, 0.0)),
        _link("q3_housing", [_module("q3 module", 0.0)]),
        _joint("q3", "q3_housing", "middle_link", (0.0, 0.0, 0.0), (0.0, 0.0, 1.0)),
        _link("middle_link", middle_parts, _cylinder_geom(MIDDLE_LINK_RADIUS, lm, 0.0)),
        arm_unit if arm_parent == "middle_link" else "",
        _joint("q4", "middle_link", "q5_housing", (lm, 0.0, 0.0), (0.0, 1.0, 0.0)),
        _link("q5_housing", [_module("q5 module", 0.0)]),
        _joint("q5", "q5_housing", "q6_housing", (0.0, 0.0, 0.0), (0.0, 0.0, 1.0)),
        _link("q6_housing", [_module("q6 module", 0.0)]),
        _joint("q6", "q6_housing", "end_link", (0.0, 0.0, 0.0), (1.0, 0.0, 0.0)),
        _link(
            "end_link",
            [
                _Part(
                    "end effector link",
                    END_LINK_MASS,
                    (le / 2, 0, 0),
                    _cylinder_x(END_LINK_MASS, END_LINK_RADIUS, le),
                )
            ],
            _cylinder_geom(END_LINK_RADIUS, le, 0.0),
        ),
        _joint("end_effector_mount", "end_link", "end_effector", (le, 0.0, 0.0), None),
        "  <!-- The end-effector frame: tool flange at the tip of the end link (massless). -->\n",
        _link("end_effector", []),
        arm_unit if arm_parent != "middle_link" else "",
        "</robot>\n",
    ]
    return "".join(out)


def _toml(name: str, summary: str) -> str:
    joints = []
    for j in JOINT_ORDER:
        torque = PITCH_STALL_TORQUE if j.startswith("beta") else LINK_STALL_TORQUE
        servo = "XL430-W250-T" if j.startswith("beta") else "XH430-W350-R"
        joints.append(
            f'[[joints]]\nname = "{j}"\nservo = "{servo}"\nstall_torque = {_f(torque)}  # N m\n'
        )
    rotors = []
    for i, (unit, side) in enumerate(
        [("foot_unit", 1), ("foot_unit", -1), ("arm_unit", -1), ("arm_unit", 1)], start=1
    ):
        # sigma_i = (-1)^(i+1). The arm pair is mirrored (rotor 3 at -y) so equal spins sit
        # on a diagonal, as on a quadrotor: otherwise roll and yaw torques are proportional
        # in straight configurations and Q-bar loses rank (rho = 0, eq. 65).
        spin = 1 if i % 2 == 1 else -1
        rotors.append(
            f'[[rotors]]\nname = "rotor{i}"\nparent = "{unit}_pitch"\n'
            f"offset = [0.0, {_f(side * ROTOR_SPACING / 2)}, {_f(ROTOR_HEIGHT)}]\n"
            f"axis = [0.0, 0.0, 1.0]\nspin = {spin}\n"
            f"drag_to_thrust = {_f(DRAG_TO_THRUST)}  # c of eq. (9) [m], ASSUMPTION\n"
            f"thrust_min = {_f(THRUST_MIN)}\nthrust_max = {_f(THRUST_MAX)}\n"
            f"diameter = {_f(ROTOR_DIAMETER)}\n"
        )
    return f"""# {name}: what URDF cannot hold. Generated by rdm.descriptions; do not edit by hand.
# {summary}
# Every ASSUMPTION (values the paper does not give) is listed in docs/model.md.
name = "{name}"
urdf = "{name}.urdf"
# Order of q in every API: link joints q1..q6, then each vectoring apparatus (roll, pitch).
joint_order = [{", ".join(f'"{j}"' for j in JOINT_ORDER)}]

[frames]
# Named frames: URDF link names. The foot frame's origin is the contact face centre of the
# plate, z out of the contact face, y along the q1 axis.
foot = "foot"
end_effector = "end_effector"

[foot]
plate_size = [{_f(FOOT_PLATE_SIZE[0])}, {_f(FOOT_PLATE_SIZE[1])}]  # x, y [m] (Table IV)
# Placeholders from Table VII (mu_x = mu_y, mu_z); the real surface decides.
friction_xy = 0.9
friction_z = 0.5

[[vectoring_units]]
name = "foot_unit"
roll_joint = "alpha1"
pitch_joint = "beta1"
rotors = ["rotor1", "rotor2"]

[[vectoring_units]]
name = "arm_unit"
roll_joint = "alpha2"
pitch_joint = "beta2"
rotors = ["rotor3", "rotor4"]

[sensors.foot_wrench]
frame = "foot"
model = "CFS034CA301U"
force_range = [150.0, 150.0, 300.0]  # N, x y z
torque_range = [4.0, 4.0, 4.0]  # N m

[sensors.end_effector_wrench]
frame = "end_effector"
model = "CFS018CA201"
force_range = [100.0, 100.0, 200.0]
torque_range = [1.0, 1.0, 1.0]

# Servo stall torques (position limits live in the URDF <limit> tags).
{chr(10).join(joints)}
# Rotors: thrust along `axis` of the parent link frame, at `offset` in that frame;
# spin sigma_i = (-1)^(i+1) (eq. 9); thrust range of the 127 mm T-Motor prop (Sec. VI-B).
{chr(10).join(rotors)}"""


def build_description(
    layout: str = "rdm", arm_unit_position: float = 1.0, foot_unit_position: float = 1.0
) -> Description:
    """Generate a description.

    Args:
        layout: ``"rdm"`` (foot unit at the root-link tip, arm unit on the middle link) or
            ``"rcm"`` (both units on the root link: the rotor-concentrated comparison robot).
        arm_unit_position: for ``"rdm"``, where the arm unit sits along the middle link as a
            fraction of its length: 0 root, 0.5 middle, 1 end (Table II). Ignored for RCM.
        foot_unit_position: for ``"rdm"``, where the foot unit sits along the root link as a
            fraction of its length from the root joint (the plate): 1 the far tip (shipped),
            0.3 beside the plate (the perching-envelope candidate). Ignored for RCM.
    """
    if layout == "rdm":
        if not 0.0 <= arm_unit_position <= 1.0:
            raise ValueError(f"arm_unit_position must lie in [0, 1], got {arm_unit_position}")
        if not 0.0 <= foot_unit_position <= 1.0:
            raise ValueError(f"foot_unit_position must lie in [0, 1], got {foot_unit_position}")
        urdf = _urdf(
            "rdm",
            foot_unit_position * ROOT_LINK_LENGTH,
            "middle_link",
            arm_unit_position * MIDDLE_LINK_LENGTH,
        )
        summary = (
            f"RDM: foot unit at the root-link tip, arm unit at fraction {_f(arm_unit_position)} "
            "(0 root, 1 end) of the middle link."
        )
        name = "rdm" if arm_unit_position == 1.0 else f"rdm_arm{round(arm_unit_position * 100)}"
        if foot_unit_position != 1.0:
            name += f"_foot{round(foot_unit_position * 100)}"
            summary += f" Foot unit at fraction {_f(foot_unit_position)} of the root link."
    elif layout == "rcm":
        # Both units on the root link, ROTOR_SPACING apart along it (a quadrotor square).
        urdf = _urdf("rcm", ROOT_LINK_LENGTH - ROTOR_SPACING, "root_link", ROOT_LINK_LENGTH)
        summary = "RCM: both vectoring apparatuses at the root-link tip (Sec. II-A-3)."
        name = "rcm"
    else:
        raise ValueError(f"layout must be 'rdm' or 'rcm', got {layout!r}")
    if name != layout:
        urdf = urdf.replace('<robot name="rdm">', f'<robot name="{name}">')
    return Description(name, urdf, _toml(name, summary))


def shipped_directory() -> Path:
    """Source-tree directory of the shipped descriptions (``rdm/data/robots``)."""
    return Path(__file__).resolve().parent / "data" / "robots"


#: Where the foot unit sits along the root link (fraction from the plate) in the shipped
#: ``rdm_foot10`` description: 0.04 m from the q1 axis, its rotor plane 0.06 m under the
#: ceiling when the root link hangs from it (the "foot at plate" perching candidate of
#: :mod:`rdm.scenarios.perch_envelope`; docs/scenarios.md "perching").
#: ASSUMPTION: the paper's "tip of the root link" read as its root end (at the foot plate).
FOOT_AT_PLATE = 0.1


def shipped_descriptions() -> tuple[Description, ...]:
    """Every description shipped under ``rdm/data/robots``: the RDM, the RCM and the RDM
    with its foot unit at the plate (:data:`FOOT_AT_PLATE`)."""
    return (
        build_description("rdm"),
        build_description("rcm"),
        build_description("rdm", foot_unit_position=FOOT_AT_PLATE),
    )


def main() -> None:
    """Regenerate the shipped descriptions (:func:`shipped_descriptions`)."""
    for desc in shipped_descriptions():
        path = desc.write(shipped_directory() / desc.name)
        print(f"wrote {path[0]} and {path[1]}")


if __name__ == "__main__":
    main()
