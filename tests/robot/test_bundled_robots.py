"""The bundled robots: every one loads; diego and finger match the thesis (Table 1.2, §2.5.1-2.5.2)
and the brief (counts, mass, observability, chamber schema); scripts/make_robots.py reproduces them.
"""

from __future__ import annotations

import importlib.util
import sys
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from diegocal.io import load_yaml
from diegocal.robot import (
    BUNDLED_ROBOTS,
    load_robot,
    markers_jacobian,
    pot_transmission,
    pot_transmission_jacobian,
    predict_pots,
)

ROBOT_DIRS = sorted(p.parent for p in BUNDLED_ROBOTS.glob("*/sensors.yaml"))
SCRIPT = BUNDLED_ROBOTS.parent / "scripts" / "make_robots.py"
GIMBALS = {"torso": ("torso_pitch", "torso_roll"), "neck": ("neck_pitch", "neck_roll")}
GIMBALS |= {f"{s}_ankle": (f"{s}_ankle_pitch", f"{s}_ankle_roll") for s in "rl"}


def nominal(robot):
    return (
        np.array([p.gain for p in robot.sensors.pots]),
        np.array([p.bias for p in robot.sensors.pots]),
    )


def test_diego_and_finger_are_bundled():
    assert {"diego", "finger"} <= {p.name for p in ROBOT_DIRS}


@pytest.mark.parametrize("directory", ROBOT_DIRS, ids=[p.name for p in ROBOT_DIRS])
def test_every_bundled_robot_loads(directory):
    robot = load_robot(directory)
    assert robot.n_joints >= 1
    assert np.isfinite(robot.lower).all() and np.isfinite(robot.upper).all()
    assert (robot.lower < robot.upper).all()
    # every movable URDF joint declares <limit effort velocity lower upper>, effort/velocity > 0
    root = ET.parse(directory / robot.sensors.urdf).getroot()
    for joint in root.iter("joint"):
        if joint.get("type") == "fixed":
            continue
        limit = joint.find("limit")
        assert limit is not None, joint.get("name")
        assert float(limit.get("effort")) > 0 and float(limit.get("velocity")) > 0, joint.get(
            "name"
        )
        assert limit.get("lower") is not None and limit.get("upper") is not None, joint.get("name")
    names = set(robot.sensors.marker_names)
    assert len(names) == len(robot.sensors.markers)
    assert all(m.link != robot.sensors.base_link for m in robot.sensors.markers)
    gain, bias = nominal(robot)
    assert np.isfinite(predict_pots(robot, robot.neutral(), gain, bias)).all()


@pytest.mark.parametrize("name", ["diego", "finger"])
def test_generated_inertias_are_physical(name, bundled):
    """make_robots.py's links (uniform boxes/cylinders): positive moments, triangle inequality."""
    robot = bundled(name)
    for inertia in robot.model.inertias[1:]:
        assert inertia.mass > 0
        moments = np.linalg.eigvalsh(inertia.inertia)
        assert moments.min() > 0
        assert moments.sum() >= 2 * moments.max() - 1e-12


# ----------------------------------------------------------------------------- diego
def test_diego_structure(bundled):
    robot = bundled("diego")
    model = robot.model
    assert robot.n_joints == 38
    assert robot.sensors.base_link == "waist"
    assert (
        robot._base_is_fixed()
    )  # the waist hangs from the crane: the URDF root, no floating joint
    subtree = {name: len(model.subtrees[model.getJointId(name)]) for name in robot.joint_names}
    # Table 1.2: head-neck 4, trunk 4, each arm 8, each leg 7
    assert subtree["neck_yaw"] == 4
    for s in "rl":
        assert subtree[f"{s}_clavicle"] == 8
        assert subtree[f"{s}_hip_yaw"] == 7
        assert model.parents[model.getJointId(f"{s}_hip_yaw")] == 0
    trunk = 38 - 4 - 2 * 8 - 2 * 7
    assert trunk == 4 and subtree["torso_yaw"] == 38 - 14
    assert {"r_shoulder_pitch", "r_elbow", "l_knee", "neck_pitch", "l_wrist_roll"} <= set(
        robot.joint_names
    )


def test_diego_is_130cm_tall(bundled):
    """Standing height at q = 0 (all link frames aligned with the waist), from the link visuals."""
    robot = bundled("diego")
    links = ET.parse(robot.directory / "robot.urdf").getroot().findall("link")
    origin = robot.link_poses(np.zeros(robot.n_joints), [link.get("name") for link in links])[1][0]
    top, bottom = -np.inf, np.inf
    for link, position in zip(links, origin, strict=True):
        geometry = link.find("visual/geometry")[0]
        centre = float(link.find("visual/origin").get("xyz").split()[2]) + position[2]
        half = 0.5 * float(geometry.get("length") or geometry.get("size").split()[2])
        top, bottom = max(top, centre + half), min(bottom, centre - half)
    assert top - bottom == pytest.approx(1.30, abs=0.03)


def test_diego_mass_is_35kg(bundled):
    robot = bundled("diego")
    total = sum(inertia.mass for inertia in robot.model.inertias)
    assert total == pytest.approx(35.0, abs=0.01)


def test_diego_pots(bundled, sample_q):
    robot = bundled("diego")
    pots = robot.sensors.pots
    rotary = [p for p in pots if p.kind == "rotary"]
    linear = [p for p in pots if p.kind == "linear"]
    assert (len(pots), len(rotary), len(linear)) == (38, 30, 8)
    gimbal_joints = {j for pair in GIMBALS.values() for j in pair}
    assert {p.joint for p in rotary} == set(robot.joint_names) - gimbal_joints
    for p in rotary:  # through gears: non-unit gain (V/rad), non-zero bias (V)
        assert 0.6 <= p.gain <= 1.6 and p.gain != 1.0
        assert p.bias != 0.0
    gain, bias = nominal(robot)
    readings = predict_pots(robot, sample_q(robot, np.random.default_rng(1), 300), gain, bias)
    assert readings.min() > 0.0 and readings.max() < 5.0  # a 0-5 V ADC over the whole range


def test_diego_gimbals_are_observable_from_their_two_linear_pots(bundled, sample_q):
    """Each pair of linear pots depends on exactly its gimbal's two axes and determines both
    (thesis Fig. 2.3d, eq. 2.19-2.20): ∂(L_a, L_b)/∂(pitch, roll) is well conditioned."""
    robot = bundled("diego")
    q = sample_q(robot, np.random.default_rng(2), 50)
    length, dlength = pot_transmission_jacobian(robot, q)
    names = robot.sensors.pot_names
    for gimbal, axes in GIMBALS.items():
        rows = [names.index(f"{gimbal}_a"), names.index(f"{gimbal}_b")]
        cols = [robot.joint_index(j) for j in axes]
        moving = np.abs(dlength[:, rows]).max(axis=(0, 1)) > 1e-9
        assert set(np.flatnonzero(moving)) == set(cols), gimbal
        assert (length[:, rows] > 0.02).all()  # the cylinder never collapses
        smallest = np.linalg.svd(dlength[:, rows][:, :, cols], compute_uv=False)[:, -1]
        assert smallest.min() > 0.01, gimbal  # m/rad


def test_diego_markers_observe_every_joint(bundled, sample_q):
    """24 markers on every other link (§2.5.1) still determine all 38 joint angles."""
    robot = bundled("diego")
    markers = robot.sensors.markers
    assert len(markers) == 24
    assert len({m.link for m in markers}) == 24
    assert all(m.link != "waist" for m in markers)
    xyz = np.array([m.xyz for m in markers])
    q = sample_q(robot, np.random.default_rng(3), 10)
    _, jac = markers_jacobian(robot, q, xyz, np.eye(3))
    singular = np.linalg.svd(jac.reshape(len(q), -1, robot.n_joints), compute_uv=False)
    assert singular[:, -1].min() > 1e-3  # m/rad: full column rank 38 everywhere sampled


CHAMBER_KEYS = {
    "name",
    "joint",
    "volume_sensor",
    "supply",
    "room",
    "side",
    "bore_area",
    "moment_arm",
    "dead_volume",
    "stroke",
}


def test_diego_chambers_schema(bundled):
    robot = bundled("diego")
    raw = load_yaml(robot.directory / "sensors.yaml")["chambers"]
    assert len(raw) == 76 == len(robot.sensors.chambers)
    by_name = {c["name"]: c for c in raw}
    pots = {p.name: p for p in robot.sensors.pots}
    gimbal_pot = {axes[0]: f"{g}_a" for g, axes in GIMBALS.items()} | {
        axes[1]: f"{g}_b" for g, axes in GIMBALS.items()
    }
    root = ET.parse(robot.directory / "robot.urdf").getroot()
    effort = {j.get("name"): float(j.find("limit").get("effort")) for j in root.iter("joint")}
    for joint in robot.joint_names:
        for side, sign in (("flex", 1), ("ext", -1)):
            c = by_name[f"{joint}.{side}"]
            assert set(c) == CHAMBER_KEYS
            assert c["joint"] == joint and c["side"] == sign
            assert (c["supply"], c["room"]) == (620.0, 100.0)  # kPa absolute
            assert np.pi * 0.005**2 <= c["bore_area"] <= np.pi * 0.010**2 * 1.001  # 10-20 mm bore
            assert 0.01 <= c["moment_arm"] <= 0.03
            assert 1e-6 <= c["dead_volume"] <= 5e-6
            assert c["stroke"] == pytest.approx(
                c["moment_arm"] * (robot.upper - robot.lower)[robot.joint_index(joint)], abs=1e-4
            )
            # the pot that measures the joint: its rotary pot, or the gimbal cylinder's linear pot
            expected = gimbal_pot.get(joint, joint)
            assert c["volume_sensor"] == expected and expected in pots
            # URDF effort is the cylinder's stall torque: area x (supply - room) x arm
            stall = c["bore_area"] * (c["supply"] - c["room"]) * 1e3 * c["moment_arm"]
            assert effort[joint] == pytest.approx(stall, rel=2e-3)


# ----------------------------------------------------------------------------- finger
def test_finger(bundled, sample_q):
    robot = bundled("finger")
    assert robot.joint_names == ("mcp_abd", "mcp_flex", "pip", "dip")
    assert robot.sensors.base_link == "palm" and robot._base_is_fixed()
    tendons = [p for p in robot.sensors.pots if p.kind == "tendon"]
    assert 4 <= len(tendons) <= 6
    for p in tendons:
        assert 2 <= len(p.moment_arms) <= 3
        assert all(0.002 <= abs(r) <= 0.015 for r in p.moment_arms.values())  # finger-sized arms, m
    markers = robot.sensors.markers
    assert 4 <= len(markers) <= 6
    assert {m.link for m in markers} == {"proximal", "middle", "distal"}
    phalanges = sum(inertia.mass for inertia in robot.model.inertias[1:])
    assert 0.02 < phalanges < 0.1  # grams, not kilograms
    q = sample_q(robot, np.random.default_rng(4), 200)
    xyz = np.array([m.xyz for m in markers])
    x, jac = markers_jacobian(robot, q, xyz, np.eye(3))
    assert np.linalg.norm(x, axis=-1).max() < 0.25  # a finger, not an arm
    singular = np.linalg.svd(jac.reshape(len(q), -1, 4), compute_uv=False)
    assert singular[:, -1].min() > 1e-3  # markers determine q, so tendon gain/bias are identifiable
    s = pot_transmission(robot, q)
    assert (s.std(axis=0) > 0).all()
    gain, bias = nominal(robot)
    readings = predict_pots(robot, q, gain, bias)
    assert readings.min() > 0.0 and readings.max() < 5.0


# ----------------------------------------------------------------------------- generator
def test_make_robots_reproduces_the_committed_files(tmp_path, monkeypatch):
    spec = importlib.util.spec_from_file_location("make_robots", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    monkeypatch.setitem(sys.modules, "make_robots", module)  # dataclasses look their module up
    spec.loader.exec_module(module)
    assert module.main(["make_robots.py", str(tmp_path)]) == 0
    for name in ("diego", "finger"):
        for file in ("robot.urdf", "sensors.yaml"):
            assert (tmp_path / name / file).read_bytes() == (
                BUNDLED_ROBOTS / name / file
            ).read_bytes(), f"{name}/{file}"
