"""Write the three small robots of thesis ch. 3 (dynamics simulator, SGP experiments).

    python scripts/make_dynamics_robots.py [ROBOTS_DIR]      (default: robots/)

- ``pendulum``       §3.1.1: one revolute joint about y; q = 0 hangs down, so the rigid-body model
  is the thesis's θ̈ = w sin θ with w = −m g l / I.  The thesis gives no mass or length: we use a
  1 kg bob on a 0.5 m massless rod (point-like bob, small inertia), i.e. w ≈ −19.6 s⁻².
- ``reaction_wheel`` §3.4.2, Fig. 3.3: an un-actuated pole joint (about y, q = 0 hangs down, q = π
  is the upright balance point) and a motor-driven flywheel at the pole's tip on a parallel axis.
  The thesis gives no physical parameters; these are plausible for a desk-top build: pole 0.30 m,
  0.20 kg (uniform rod), flywheel 0.30 kg, radius 0.08 m (disc: I = ½ m r²). The wheel is
  continuous in reality; Pinocchio's continuous joints have two position coordinates, which diegocal
  does not accept, so it is declared revolute with limits ±1e4 rad (never reached).
- ``arm3``           §3.4.4, Fig. 3.8: a 3-link arm: yaw (z) at the base, then two pitch joints (y).
  Links 0.40 / 0.35 / 0.25 m, masses 2.0 / 1.5 / 0.8 kg (uniform rods). Joint 3 has a limited
  range [−0.3, 2.3] rad; its cable-like friction near the limits is an injected effect
  (position_friction).

Each directory gets ``robot.urdf`` and ``sensors.yaml`` (base_link only: no pots, markers or
chambers; DESIGN.md's schema allows empty lists).
"""

from __future__ import annotations

import sys
from pathlib import Path

PI = 3.14159265359
HEADER = '<?xml version="1.0"?>\n<robot name="{name}">\n  <link name="base_link"/>\n'


def _rod_inertia(mass: float, length: float, axis: str = "z") -> dict:
    """Inertia (kg m²) of a uniform rod (radius 1 cm) along ``axis``, about its centre."""
    r = 0.01
    across = mass * length**2 / 12.0 + mass * r**2 / 4.0
    along = mass * r**2 / 2.0
    out = {"ixx": across, "iyy": across, "izz": across}
    out["i" + axis * 2] = along
    return out


def _link(name: str, mass: float, com: tuple, inertia: dict) -> str:
    x, y, z = com
    i = inertia
    return (
        f'  <link name="{name}">\n    <inertial>\n'
        f'      <origin xyz="{x:g} {y:g} {z:g}" rpy="0 0 0"/>\n'
        f'      <mass value="{mass:g}"/>\n'
        f'      <inertia ixx="{i["ixx"]:.8g}" ixy="0" ixz="0" iyy="{i["iyy"]:.8g}" iyz="0"'
        f' izz="{i["izz"]:.8g}"/>\n'
        "    </inertial>\n  </link>\n"
    )


def _joint(
    name: str,
    parent: str,
    child: str,
    xyz: tuple,
    axis: tuple,
    lower: float,
    upper: float,
    effort: float = 100.0,
    velocity: float = 100.0,
) -> str:
    return (
        f'  <joint name="{name}" type="revolute">\n'
        f'    <parent link="{parent}"/>\n    <child link="{child}"/>\n'
        f'    <origin xyz="{xyz[0]:g} {xyz[1]:g} {xyz[2]:g}" rpy="0 0 0"/>\n'
        f'    <axis xyz="{axis[0]:g} {axis[1]:g} {axis[2]:g}"/>\n'
        f'    <limit lower="{lower:.10g}" upper="{upper:.10g}"'
        f' effort="{effort:g}" velocity="{velocity:g}"/>\n'
        "  </joint>\n"
    )


def pendulum_urdf() -> str:
    m, length = 1.0, 0.5
    bob = {"ixx": 1e-4, "iyy": 1e-4, "izz": 1e-4}
    return (
        HEADER.format(name="pendulum")
        + _link("bob", m, (0, 0, -length), bob)
        + _joint("theta", "base_link", "bob", (0, 0, 0), (0, 1, 0), -PI, PI)
        + "</robot>\n"
    )


def reaction_wheel_urdf() -> str:
    pole_m, pole_l = 0.20, 0.30
    wheel_m, wheel_r = 0.30, 0.08
    disc_axis = 0.5 * wheel_m * wheel_r**2
    disc_across = 0.25 * wheel_m * wheel_r**2
    wheel = {"ixx": disc_across, "iyy": disc_axis, "izz": disc_across}
    return (
        HEADER.format(name="reaction_wheel")
        + _link("pole", pole_m, (0, 0, -pole_l / 2), _rod_inertia(pole_m, pole_l))
        + _link("wheel", wheel_m, (0, 0, 0), wheel)
        + _joint("pole", "base_link", "pole", (0, 0, 0), (0, 1, 0), -100.0, 100.0, effort=5.0)
        + _joint(
            "wheel",
            "pole",
            "wheel",
            (0, 0.03, -pole_l),
            (0, 1, 0),
            -1e4,
            1e4,
            effort=2.0,
            velocity=1000.0,
        )
        + "</robot>\n"
    )


def arm3_urdf() -> str:
    (l1, l2, l3), (m1, m2, m3) = (0.40, 0.35, 0.25), (2.0, 1.5, 0.8)
    out = HEADER.format(name="arm3")
    # link1 rises vertically from the base (yaw joint); links 2 and 3 extend along their x axes.
    out += _link("link1", m1, (0, 0, l1 / 2), _rod_inertia(m1, l1, "z"))
    out += _link("link2", m2, (l2 / 2, 0, 0), _rod_inertia(m2, l2, "x"))
    out += _link("link3", m3, (l3 / 2, 0, 0), _rod_inertia(m3, l3, "x"))
    out += '  <link name="tool"/>\n'
    out += _joint("joint1", "base_link", "link1", (0, 0, 0), (0, 0, 1), -2.8, 2.8, effort=60.0)
    out += _joint("joint2", "link1", "link2", (0, 0, l1), (0, 1, 0), -2.0, 2.0, effort=60.0)
    out += _joint("joint3", "link2", "link3", (l2, 0, 0), (0, 1, 0), -0.3, 2.3, effort=30.0)
    out += (
        '  <joint name="tool_fixed" type="fixed">\n    <parent link="link3"/>\n'
        f'    <child link="tool"/>\n    <origin xyz="{l3:g} 0 0" rpy="0 0 0"/>\n  </joint>\n'
    )
    return out + "</robot>\n"


SENSORS = "urdf: robot.urdf\nbase_link: base_link\npots: []\nmarkers: []\nchambers: []\n"
ROBOTS = {"pendulum": pendulum_urdf, "reaction_wheel": reaction_wheel_urdf, "arm3": arm3_urdf}


def write_robots(root: Path) -> list[Path]:
    """Write every robot directory under ``root``; returns the directories written."""
    out = []
    for name, make in ROBOTS.items():
        d = root / name
        d.mkdir(parents=True, exist_ok=True)
        (d / "robot.urdf").write_text(make())
        (d / "sensors.yaml").write_text(SENSORS)
        out.append(d)
    return out


if __name__ == "__main__":
    default = Path(__file__).resolve().parents[1] / "robots"
    target = Path(sys.argv[1]) if len(sys.argv) > 1 else default
    for d in write_robots(target):
        print(d)
