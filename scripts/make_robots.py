"""Write the bundled robots ``diego`` and ``finger`` (robot.urdf + sensors.yaml, DESIGN.md schema).

    python scripts/make_robots.py [ROBOTS_DIR]      (default: robots/)

The output is deterministic (the nominal gains/biases come from ``np.random.default_rng(2013)``),
so re-running it reproduces the committed files byte for byte (tests/robot checks that).

``diego`` — the pneumatic humanoid of thesis Table 1.2, §1.1 and §2.5.1: 130 cm, 35 kg, 38 body
joints (head-neck 4, trunk 4, each arm 8, each leg 7), base link ``waist`` hung from a crane (the
URDF root, fixed to the world). Four joints are 2-DoF gimbals (Fig. 2.3d / 2.5a), each two revolute
axes (pitch about y, then roll about x) through a small cross link, measured by two linear pots
whose anchors sit 2.5-5 cm off the axes on the links either side: ``neck``, ``torso`` (waist/
chest) and the two ankles (the classic two-cylinder ankle). The other 30 joints are hinge joints
with gear-transmitted rotary pots (Fig. 2.5b): nominal gain 0.6-1.6 V/rad and a bias that puts mid
range near 2.5 V. 24 markers sit on every other link counting from the base (§2.5.1), moved one
link outward where that link is a gimbal cross (no room for a marker there) and with the branch
link ``chest`` and the even-depth end links (head, hands) added: every joint is observed. Nominal
marker positions are a rough CAD guess (on the link surface, 2-9 cm off the link origin), not the
link origin: a marker at the origin of the last link of a chain lies on its joint axis. Frames:
x forward, y left, z up; q = 0 stands upright with the arms hanging. Links are uniform cylinders
(limbs) or boxes (trunk, head) whose inertia tensors follow from their mass and size; the masses
(a 1-year-old's proportions, big head and trunk) are scaled to sum to exactly 35 kg.

Each joint has two pneumatic chambers (flexor, extensor: 76). ``volume_sensor`` is the joint's
rotary pot or, for a gimbal axis, the linear pot of the cylinder that drives it (pitch -> ``_a``,
roll -> ``_b``). Pressures are kPa absolute (supply 620, room 100). ``stroke`` = moment arm x joint
range; URDF effort = bore area x (supply - room) x moment arm.

``finger`` — a small tendon-driven finger (Fig. 2.3e, §2.5.2): base ``palm`` fixed, joints
mcp_abd, mcp_flex, pip, dip; five tendons (kind tendon, moment arms fixed, spanning 2-3 joints),
rotary (Hall-effect) pots on mcp_abd and dip, five markers on the phalanges; finger-sized geometry
(cm) and masses (g). The markers determine q, so tendon gains are identifiable. Offsets are subtler:
with marker positions and the mocap frame calibrated too, two joint zeros are gauge freedoms: dip
(its markers all sit on its own child link; rotating them about its axis absorbs an offset) and
mcp_abd (it moves every marker from a base-fixed axis; rotating the mocap frame absorbs an
offset). One pot reading each must keep its nominal bias: the two Hall sensors take that role, so
every tendon's gain and bias is identifiable. In diego the leaf joints (head_pitch, wrist rolls,
toes) have rotary pots for the same reason; no diego joint moves every marker. tests/robot checks
both robots' full calibration Jacobian (q, gain, bias, marker xyz, mocap frame) has full rank once
those gauge biases are fixed.
"""

from __future__ import annotations

import math
import sys
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from diegocal.io import write_text  # noqa: E402

SUPPLY_KPA = 620.0
ROOM_KPA = 100.0
TOTAL_MASS = 35.0
AXES = {"x": (1, 0, 0), "y": (0, 1, 0), "z": (0, 0, 1)}


# ----------------------------------------------------------------------------- model description
@dataclass
class Link:
    """A rigid link: ``shape`` ('cyl', radius, length) along z or ('box', sx, sy, sz), in m,
    centred at ``com`` (link frame); mass in kg."""

    name: str
    mass: float
    shape: tuple
    com: tuple = (0.0, 0.0, 0.0)


@dataclass
class Joint:
    """A revolute joint; ``xyz`` is its origin in the parent frame (m); rad, N m, rad/s."""

    name: str
    parent: str
    child: str
    xyz: tuple
    axis: str
    lower: float
    upper: float
    effort: float = 5.0
    velocity: float = 4.0


@dataclass
class RobotSpec:
    name: str
    links: list = field(default_factory=list)
    joints: list = field(default_factory=list)


def inertia(link: Link) -> tuple[float, float, float]:
    """Principal moments (kg m²) about the centre of mass of a uniform cylinder (axis z) or box."""
    m = link.mass
    if link.shape[0] == "cyl":
        _, r, h = link.shape
        across = m * (3 * r**2 + h**2) / 12.0
        return across, across, m * r**2 / 2.0
    _, sx, sy, sz = link.shape
    return m * (sy**2 + sz**2) / 12.0, m * (sx**2 + sz**2) / 12.0, m * (sx**2 + sy**2) / 12.0


def _fmt(v: float) -> str:
    return f"{v:.6g}"


def _vec(v) -> str:
    return " ".join(_fmt(float(x)) for x in v)


def urdf_text(spec: RobotSpec) -> str:
    """The URDF of ``spec``: inertial and visual blocks per link, revolute joints with limits."""
    robot = ET.Element("robot", name=spec.name)
    for link in spec.links:
        el = ET.SubElement(robot, "link", name=link.name)
        inert = ET.SubElement(el, "inertial")
        ET.SubElement(inert, "origin", xyz=_vec(link.com), rpy="0 0 0")
        ET.SubElement(inert, "mass", value=_fmt(link.mass))
        ixx, iyy, izz = inertia(link)
        ET.SubElement(
            inert, "inertia", ixx=_fmt(ixx), ixy="0", ixz="0", iyy=_fmt(iyy), iyz="0", izz=_fmt(izz)
        )
        vis = ET.SubElement(el, "visual")
        ET.SubElement(vis, "origin", xyz=_vec(link.com), rpy="0 0 0")
        geom = ET.SubElement(vis, "geometry")
        if link.shape[0] == "cyl":
            ET.SubElement(geom, "cylinder", radius=_fmt(link.shape[1]), length=_fmt(link.shape[2]))
        else:
            ET.SubElement(geom, "box", size=_vec(link.shape[1:]))
    for j in spec.joints:
        el = ET.SubElement(robot, "joint", name=j.name, type="revolute")
        ET.SubElement(el, "parent", link=j.parent)
        ET.SubElement(el, "child", link=j.child)
        ET.SubElement(el, "origin", xyz=_vec(j.xyz), rpy="0 0 0")
        ET.SubElement(el, "axis", xyz=_vec(AXES[j.axis]))
        ET.SubElement(
            el,
            "limit",
            effort=_fmt(j.effort),
            velocity=_fmt(j.velocity),
            lower=_fmt(j.lower),
            upper=_fmt(j.upper),
        )
    ET.indent(robot, space="  ")
    return '<?xml version="1.0"?>\n' + ET.tostring(robot, encoding="unicode") + "\n"


def sensors_text(header: str, base_link: str, pots, markers, chambers) -> str:
    """sensors.yaml with one flow-style line per entry, as in DESIGN.md."""

    def line(entry) -> str:
        return (
            "  - "
            + yaml.safe_dump(entry, default_flow_style=True, sort_keys=False, width=1000).strip()
        )

    out = [f"# {h}" if h else "#" for h in header.splitlines()]
    out += ["urdf: robot.urdf", f"base_link: {base_link}"]
    for key, entries in (("pots", pots), ("markers", markers), ("chambers", chambers)):
        out.append(f"{key}:" if entries else f"{key}: []")
        out += [line(e) for e in entries]
    return "\n".join(out) + "\n"


def _r(x: float, nd: int = 4) -> float:
    return float(round(float(x), nd))


def _xyz(v) -> list[float]:
    return [_r(x) for x in v]


# ----------------------------------------------------------------------------- diego
# Gimbals: name -> (parent link, pitch joint, roll joint, child link, centre in parent frame,
# anchor offsets (x, |y|, z) from the centre on the parent and on the child side).
GIMBALS = {
    "torso": (
        "lumbar",
        "torso_pitch",
        "torso_roll",
        "abdomen",
        (0, 0, 0.06),
        (0.05, 0.05, -0.05),
        (0.05, 0.05, 0.04),
    ),
    "neck": (
        "neck_base",
        "neck_pitch",
        "neck_roll",
        "neck",
        (0, 0, 0.04),
        (0.025, 0.025, -0.035),
        (0.025, 0.025, 0.025),
    ),
    "r_ankle": (
        "r_shank",
        "r_ankle_pitch",
        "r_ankle_roll",
        "r_foot",
        (0, 0, -0.21),
        (-0.035, 0.03, 0.13),
        (-0.045, 0.03, -0.015),
    ),
    "l_ankle": (
        "l_shank",
        "l_ankle_pitch",
        "l_ankle_roll",
        "l_foot",
        (0, 0, -0.21),
        (-0.035, 0.03, 0.13),
        (-0.045, 0.03, -0.015),
    ),
}

# Pneumatic cylinder classes: (bore diameter m, moment arm m, dead volume m³).
CYLINDERS = {
    "large": (0.020, 0.030, 5.0e-6),
    "medium": (0.016, 0.020, 3.0e-6),
    "small": (0.010, 0.012, 1.2e-6),
}


def diego_spec() -> tuple[RobotSpec, dict, list]:
    """Links, joints, cylinder class per joint and marker list (link, nominal xyz) of diego."""
    spec = RobotSpec("diego")
    L, J = spec.links.append, spec.joints.append
    size: dict[str, str] = {}

    def joint(name, parent, child, xyz, axis, lower, upper, cyl):
        J(Joint(name, parent, child, xyz, axis, lower, upper))
        size[name] = cyl

    # trunk (4): yaw, gimbal (pitch, roll), chest pitch
    L(Link("waist", 4.0, ("box", 0.16, 0.20, 0.10), (0, 0, 0.0)))
    L(Link("lumbar", 1.2, ("cyl", 0.06, 0.08), (0, 0, 0.03)))
    L(Link("torso_cross", 0.15, ("box", 0.04, 0.04, 0.02)))
    L(Link("abdomen", 3.0, ("box", 0.14, 0.20, 0.12), (0, 0, 0.06)))
    L(Link("chest", 6.0, ("box", 0.15, 0.24, 0.22), (0, 0, 0.10)))
    joint("torso_yaw", "waist", "lumbar", (0, 0, 0.08), "z", -0.6, 0.6, "large")
    joint("torso_pitch", "lumbar", "torso_cross", (0, 0, 0.06), "y", -0.35, 0.6, "large")
    joint("torso_roll", "torso_cross", "abdomen", (0, 0, 0), "x", -0.4, 0.4, "large")
    joint("chest_pitch", "abdomen", "chest", (0, 0, 0.12), "y", -0.3, 0.5, "large")
    # head-neck (4): yaw, gimbal (pitch, roll), head pitch
    L(Link("neck_base", 0.3, ("cyl", 0.035, 0.04), (0, 0, 0.02)))
    L(Link("neck_cross", 0.08, ("box", 0.025, 0.025, 0.015)))
    L(Link("neck", 0.4, ("cyl", 0.03, 0.06), (0, 0, 0.03)))
    L(Link("head", 3.2, ("box", 0.20, 0.18, 0.20), (0.02, 0, 0.09)))
    joint("neck_yaw", "chest", "neck_base", (0, 0, 0.18), "z", -1.2, 1.2, "small")
    joint("neck_pitch", "neck_base", "neck_cross", (0, 0, 0.04), "y", -0.5, 0.6, "small")
    joint("neck_roll", "neck_cross", "neck", (0, 0, 0), "x", -0.45, 0.45, "small")
    joint("head_pitch", "neck", "head", (0, 0, 0.06), "y", -0.4, 0.4, "small")
    markers = [
        ("lumbar", (0.06, 0.03, 0.03)),
        ("abdomen", (0.08, -0.03, 0.06)),
        ("chest", (0.08, 0.04, 0.12)),
        ("neck_base", (0.035, 0.02, 0.02)),
        ("neck", (0.03, -0.02, 0.04)),
        ("head", (0.12, 0.03, 0.09)),
    ]

    for s, y in (("r", -1.0), ("l", 1.0)):
        # arm (8): collar elevation, shoulder pitch/roll/yaw, elbow, wrist yaw/pitch/roll
        L(Link(f"{s}_collar", 0.4, ("cyl", 0.025, 0.09), (0, y * 0.045, 0)))
        L(Link(f"{s}_shoulder", 0.25, ("cyl", 0.03, 0.04), (0, y * 0.015, 0)))
        L(Link(f"{s}_upper_arm", 0.9, ("cyl", 0.035, 0.08), (0, 0, -0.04)))
        L(Link(f"{s}_arm_twist", 0.45, ("cyl", 0.03, 0.10), (0, 0, -0.05)))
        L(Link(f"{s}_forearm", 0.55, ("cyl", 0.03, 0.07), (0, 0, -0.035)))
        L(Link(f"{s}_forearm_twist", 0.3, ("cyl", 0.025, 0.09), (0, 0, -0.045)))
        L(Link(f"{s}_wrist", 0.08, ("box", 0.03, 0.03, 0.015)))
        L(Link(f"{s}_hand", 0.45, ("box", 0.03, 0.07, 0.10), (0, 0, -0.065)))
        sign = (
            y  # abduction/elevation away from the body is -x rotation on the right, +x on the left
        )
        joint(
            f"{s}_clavicle", "chest", f"{s}_collar", (0, y * 0.04, 0.16), "x", -0.25, 0.25, "small"
        )
        joint(
            f"{s}_shoulder_pitch",
            f"{s}_collar",
            f"{s}_shoulder",
            (0, y * 0.09, 0),
            "y",
            -2.8,
            0.8,
            "large",
        )
        lo, hi = (-1.6, 0.2) if sign < 0 else (-0.2, 1.6)
        joint(
            f"{s}_shoulder_roll",
            f"{s}_shoulder",
            f"{s}_upper_arm",
            (0, y * 0.025, 0),
            "x",
            lo,
            hi,
            "large",
        )
        joint(
            f"{s}_shoulder_yaw",
            f"{s}_upper_arm",
            f"{s}_arm_twist",
            (0, 0, -0.08),
            "z",
            -1.2,
            1.2,
            "medium",
        )
        joint(
            f"{s}_elbow", f"{s}_arm_twist", f"{s}_forearm", (0, 0, -0.10), "y", -2.3, 0.05, "medium"
        )
        joint(
            f"{s}_wrist_yaw",
            f"{s}_forearm",
            f"{s}_forearm_twist",
            (0, 0, -0.07),
            "z",
            -1.3,
            1.3,
            "small",
        )
        joint(
            f"{s}_wrist_pitch",
            f"{s}_forearm_twist",
            f"{s}_wrist",
            (0, 0, -0.09),
            "y",
            -1.0,
            1.0,
            "small",
        )
        joint(f"{s}_wrist_roll", f"{s}_wrist", f"{s}_hand", (0, 0, -0.015), "x", -0.5, 0.5, "small")
        # leg (7): hip yaw/roll/pitch, knee, ankle gimbal (pitch, roll), toe
        L(Link(f"{s}_hip", 0.5, ("cyl", 0.04, 0.04), (0, 0, -0.02)))
        L(Link(f"{s}_hip_block", 0.35, ("box", 0.05, 0.05, 0.04)))
        L(Link(f"{s}_thigh", 2.4, ("cyl", 0.05, 0.23), (0, 0, -0.115)))
        L(Link(f"{s}_shank", 1.4, ("cyl", 0.04, 0.21), (0, 0, -0.105)))
        L(Link(f"{s}_ankle", 0.1, ("box", 0.03, 0.03, 0.02)))
        L(Link(f"{s}_foot", 0.6, ("box", 0.14, 0.07, 0.04), (0.03, 0, -0.03)))
        L(Link(f"{s}_toes", 0.15, ("box", 0.05, 0.07, 0.02), (0.025, 0, 0.0)))
        joint(f"{s}_hip_yaw", "waist", f"{s}_hip", (0, y * 0.07, -0.05), "z", -0.6, 0.6, "medium")
        lo, hi = (-0.6, 0.3) if sign < 0 else (-0.3, 0.6)
        joint(f"{s}_hip_roll", f"{s}_hip", f"{s}_hip_block", (0, 0, -0.04), "x", lo, hi, "large")
        joint(f"{s}_hip_pitch", f"{s}_hip_block", f"{s}_thigh", (0, 0, 0), "y", -1.8, 0.5, "large")
        joint(f"{s}_knee", f"{s}_thigh", f"{s}_shank", (0, 0, -0.23), "y", -0.05, 2.3, "large")
        joint(
            f"{s}_ankle_pitch", f"{s}_shank", f"{s}_ankle", (0, 0, -0.21), "y", -0.6, 0.5, "medium"
        )
        joint(f"{s}_ankle_roll", f"{s}_ankle", f"{s}_foot", (0, 0, 0), "x", -0.35, 0.35, "medium")
        joint(f"{s}_toe", f"{s}_foot", f"{s}_toes", (0.09, 0, -0.05), "y", -0.5, 0.5, "small")
        markers += [
            (f"{s}_collar", (0.02, y * 0.06, 0.02)),
            (f"{s}_upper_arm", (0.035, y * 0.01, -0.05)),
            (f"{s}_forearm", (0.03, y * 0.015, -0.04)),
            (f"{s}_wrist", (0.02, y * 0.02, -0.02)),
            (f"{s}_hand", (0.025, y * 0.01, -0.07)),
            (f"{s}_hip", (0.04, y * 0.04, -0.01)),
            (f"{s}_thigh", (0.05, y * 0.02, -0.12)),
            (f"{s}_foot", (0.08, y * 0.045, -0.035)),
            (f"{s}_toes", (0.045, y * 0.025, 0.012)),
        ]
    # scale the masses to exactly 35 kg; the rounding remainder goes to the waist
    scale = TOTAL_MASS / sum(link.mass for link in spec.links)
    for link in spec.links:
        link.mass = _r(link.mass * scale)
    spec.links[0].mass = _r(TOTAL_MASS - sum(link.mass for link in spec.links[1:]))
    for j in spec.joints:
        bore, arm, _ = CYLINDERS[size[j.name]]
        j.effort = _r(math.pi * bore**2 / 4 * (SUPPLY_KPA - ROOM_KPA) * 1e3 * arm, 2)
    return spec, size, markers


def _gain_bias(rng, gain_lo, gain_hi, s_lo, s_hi, span_v=4.4) -> tuple[float, float]:
    """A gain in [gain_lo, gain_hi] and a bias keeping readings of s in [s_lo, s_hi] in 0-5 V."""
    span = s_hi - s_lo
    gain = rng.uniform(gain_lo, min(gain_hi, span_v / span))
    slack = min(0.3, 0.5 * (4.8 - gain * span))
    bias = 2.5 - gain * 0.5 * (s_lo + s_hi) + rng.uniform(-slack, slack)
    return _r(gain, 3), _r(bias, 3)


def _gimbal_lengths(spec: RobotSpec, gimbal, a, b, n: int = 41) -> np.ndarray:
    """Anchor distance |R_y(pitch) R_x(roll) b - a| over a grid of the gimbal's range (m)."""
    lim = {j.name: (j.lower, j.upper) for j in spec.joints}
    pitch, roll = np.meshgrid(np.linspace(*lim[gimbal[1]], n), np.linspace(*lim[gimbal[2]], n))
    cp, sp, cr, sr = np.cos(pitch), np.sin(pitch), np.cos(roll), np.sin(roll)
    rb = np.stack(
        [
            cp * b[0] + sp * (sr * b[1] + cr * b[2]),
            cr * b[1] - sr * b[2],
            -sp * b[0] + cp * (sr * b[1] + cr * b[2]),
        ],
        axis=-1,
    )
    return np.linalg.norm(rb - a, axis=-1)


def diego_sensors(spec: RobotSpec, size: dict, markers: list, rng: np.random.Generator):
    """pots (30 rotary + 8 linear), markers (24) and chambers (76) of diego."""
    gimbal_axes = {}
    for g, (_, pitch, roll, _, _, _, _) in GIMBALS.items():
        gimbal_axes[pitch] = f"{g}_a"
        gimbal_axes[roll] = f"{g}_b"
    pots = []
    for j in spec.joints:
        if j.name in gimbal_axes:
            continue
        gain, bias = _gain_bias(rng, 0.6, 1.6, j.lower, j.upper)  # V/rad through the pot's gears
        pots.append({"name": j.name, "kind": "rotary", "joint": j.name, "gain": gain, "bias": bias})
    for g, (parent, _, _, child, centre, lo, hi) in GIMBALS.items():
        for suffix, y in (("a", 1.0), ("b", -1.0)):
            a = np.array(centre) + np.array(
                [lo[0], y * lo[1], lo[2]]
            )  # parent-side anchor, parent frame
            b = np.array(
                [hi[0], y * hi[1], hi[2]]
            )  # child-side anchor, child frame = gimbal centre
            lengths = _gimbal_lengths(spec, GIMBALS[g], a - np.array(centre), b)
            gain, bias = _gain_bias(rng, 30.0, 60.0, lengths.min(), lengths.max())  # V/m
            pots.append(
                {
                    "name": f"{g}_{suffix}",
                    "kind": "linear",
                    "anchors": [{"link": parent, "xyz": _xyz(a)}, {"link": child, "xyz": _xyz(b)}],
                    "gain": gain,
                    "bias": bias,
                }
            )
    mk = [
        {"name": f"m{i + 1:02d}", "link": link, "xyz": _xyz(xyz)}
        for i, (link, xyz) in enumerate(markers)
    ]
    chambers = []
    for j in spec.joints:
        bore, arm, dead = CYLINDERS[size[j.name]]
        for side, sign in (("flex", 1), ("ext", -1)):
            chambers.append(
                {
                    "name": f"{j.name}.{side}",
                    "joint": j.name,
                    "volume_sensor": gimbal_axes.get(j.name, j.name),
                    "supply": SUPPLY_KPA,
                    "room": ROOM_KPA,
                    "side": sign,
                    "bore_area": float(f"{math.pi * bore**2 / 4:.4g}"),
                    "moment_arm": arm,
                    "dead_volume": dead,
                    "stroke": _r(arm * (j.upper - j.lower)),
                }
            )
    return pots, mk, chambers


# ----------------------------------------------------------------------------- finger
def finger_spec() -> RobotSpec:
    """An index-sized finger along +x; flexion is +y rotation (curls towards -z, palm side)."""
    spec = RobotSpec("finger")
    spec.links += [
        Link("palm", 0.25, ("box", 0.09, 0.08, 0.02), (0.045, 0, 0)),
        Link("knuckle", 0.004, ("box", 0.01, 0.01, 0.01)),
        Link("proximal", 0.025, ("cyl", 0.009, 0.045), (0.0225, 0, 0)),
        Link("middle", 0.012, ("cyl", 0.008, 0.026), (0.013, 0, 0)),
        Link("distal", 0.008, ("cyl", 0.007, 0.022), (0.011, 0, 0)),
    ]
    spec.joints += [
        Joint("mcp_abd", "palm", "knuckle", (0.09, 0, 0), "z", -0.35, 0.35, 0.3, 6.0),
        Joint("mcp_flex", "knuckle", "proximal", (0.005, 0, 0), "y", -0.3, 1.55, 0.5, 6.0),
        Joint("pip", "proximal", "middle", (0.045, 0, 0), "y", -0.05, 1.75, 0.3, 6.0),
        Joint("dip", "middle", "distal", (0.026, 0, 0), "y", -0.05, 1.4, 0.2, 6.0),
    ]
    return spec


# Tendons: moment arms (m) per joint; positive arms lengthen the sensor reading with flexion.
TENDONS = {
    "fdp": {"mcp_flex": 0.010, "pip": 0.008, "dip": 0.006},  # deep flexor, spans three joints
    "fds": {"mcp_flex": 0.009, "pip": 0.007},  # superficial flexor
    "ext": {"mcp_flex": -0.008, "pip": -0.005, "dip": -0.004},  # extensor hood
    "radial_int": {"mcp_abd": 0.006, "mcp_flex": 0.005},  # interossei: abduction and flexion
    "ulnar_int": {"mcp_abd": -0.006, "mcp_flex": 0.005},
}


def finger_sensors(spec: RobotSpec, rng: np.random.Generator):
    limits = {j.name: (j.lower, j.upper) for j in spec.joints}
    pots = []
    for name, arms in TENDONS.items():
        low = sum(
            r * limits[j][0 if r > 0 else 1] for j, r in arms.items()
        )  # shortest excursion, m
        high = sum(r * limits[j][1 if r > 0 else 0] for j, r in arms.items())
        gain, bias = _gain_bias(rng, 60.0, 250.0, low, high)  # V/m of tendon excursion
        pots.append(
            {"name": name, "kind": "tendon", "moment_arms": arms, "gain": gain, "bias": bias}
        )
    for joint in (
        "mcp_abd",
        "dip",
    ):  # Hall-effect joint sensors (the Shadow hand has one per joint)
        gain, bias = _gain_bias(rng, 0.6, 1.6, *limits[joint])
        pots.append({"name": joint, "kind": "rotary", "joint": joint, "gain": gain, "bias": bias})
    markers = [
        ("proximal", (0.012, 0.004, 0.010)),
        ("proximal", (0.034, -0.004, 0.010)),
        ("middle", (0.016, 0.0, 0.009)),
        ("distal", (0.008, 0.003, 0.008)),
        ("distal", (0.018, -0.003, 0.006)),
    ]
    mk = [
        {"name": f"m{i + 1}", "link": link, "xyz": _xyz(xyz)}
        for i, (link, xyz) in enumerate(markers)
    ]
    return pots, mk, []


# ----------------------------------------------------------------------------- main
def write_robot(
    directory: Path, spec: RobotSpec, header: str, base: str, pots, markers, chambers
) -> None:
    write_text(directory / "robot.urdf", urdf_text(spec))
    write_text(directory / "sensors.yaml", sensors_text(header, base, pots, markers, chambers))


def main(argv: list[str]) -> int:
    out = Path(argv[1]) if len(argv) > 1 else ROOT / "robots"
    rng = np.random.default_rng(2013)
    spec, size, markers = diego_spec()
    write_robot(
        out / "diego",
        spec,
        "diego: pneumatic humanoid (thesis Table 1.2, §2.5.1). Written by scripts/make_robots.py.\n"
        "Pots in V (rotary: V/rad, linear: V/m); pressures kPa absolute; lengths m, areas m^2,\n"
        "volumes m^3. Marker xyz are rough CAD guesses, the seed of calibration.",
        "waist",
        *diego_sensors(spec, size, markers, rng),
    )
    finger = finger_spec()
    write_robot(
        out / "finger",
        finger,
        "finger: tendon-driven finger (thesis Fig. 2.3e, §2.5.2). By scripts/make_robots.py.\n"
        "Tendon gains in V/m of excursion (moment arms in m, fixed); Hall pots in V/rad.",
        "palm",
        *finger_sensors(finger, rng),
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv))
