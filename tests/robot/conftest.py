"""Fixtures for the robot-model tests: the bundled robots and a tiny robot built in the test.

The tiny robot exercises what the bundled ones do not: an encoder on a prismatic joint and a
``base_link`` that is not the URDF root (so ``Robot.points_jacobian`` takes its moving-base
branch): world_link -j0 (revolute z)-> l0 -slide (prismatic)-> base -j2 (revolute)-> arm
-j3 (revolute, oblique axis)-> hand.
"""

from __future__ import annotations

import copy

import numpy as np
import pytest

from diegocal.io import save_yaml, write_text
from diegocal.robot import BUNDLED_ROBOTS, load_robot

TINY_URDF = """<?xml version="1.0"?>
<robot name="tiny">
  <link name="world_link"/>
  <link name="l0"><inertial><mass value="0.2"/>
    <inertia ixx="1e-4" ixy="0" ixz="0" iyy="1e-4" iyz="0" izz="1e-4"/></inertial></link>
  <link name="base"><inertial><mass value="0.3"/>
    <inertia ixx="1e-4" ixy="0" ixz="0" iyy="1e-4" iyz="0" izz="1e-4"/></inertial></link>
  <link name="arm"><inertial><mass value="0.2"/>
    <inertia ixx="1e-4" ixy="0" ixz="0" iyy="1e-4" iyz="0" izz="1e-4"/></inertial></link>
  <link name="hand"><inertial><mass value="0.1"/>
    <inertia ixx="1e-5" ixy="0" ixz="0" iyy="1e-5" iyz="0" izz="1e-5"/></inertial></link>
  <joint name="j0" type="revolute"><parent link="world_link"/><child link="l0"/>
    <origin xyz="0 0 0.1" rpy="0 0 0"/><axis xyz="0 0 1"/>
    <limit effort="5" velocity="3" lower="-1.0" upper="1.0"/></joint>
  <joint name="slide" type="prismatic"><parent link="l0"/><child link="base"/>
    <origin xyz="0.05 0 0" rpy="0.3 0.1 0"/><axis xyz="1 0 0"/>
    <limit effort="50" velocity="1" lower="-0.1" upper="0.1"/></joint>
  <joint name="j2" type="revolute"><parent link="base"/><child link="arm"/>
    <origin xyz="0 0.02 0.1" rpy="0 0.2 0"/><axis xyz="0 1 0"/>
    <limit effort="5" velocity="3" lower="-1.5" upper="1.5"/></joint>
  <joint name="j3" type="revolute"><parent link="arm"/><child link="hand"/>
    <origin xyz="0.2 0 0" rpy="0 0 0.4"/><axis xyz="0.6 0 0.8"/>
    <limit effort="5" velocity="3" lower="-1.0" upper="1.0"/></joint>
</robot>
"""

TINY_SENSORS = {
    "urdf": "robot.urdf",
    "base_link": "base",
    "pots": [
        {"name": "slide_enc", "kind": "encoder", "joint": "slide", "bias": 0.01},
        {"name": "j2_pot", "kind": "rotary", "joint": "j2", "gain": 0.8, "bias": 2.0},
        {
            "name": "tendon",
            "kind": "tendon",
            "moment_arms": {"j2": 0.01, "j3": -0.02},
            "gain": 150.0,
            "bias": 1.0,
        },
        {
            "name": "lin_up",
            "kind": "linear",
            "anchors": [
                {"link": "l0", "xyz": [0.02, 0.03, 0.0]},
                {"link": "arm", "xyz": [0.05, 0.0, 0.02]},
            ],
            "gain": 40.0,
            "bias": -1.0,
        },
        {
            "name": "lin_base",
            "kind": "linear",
            "anchors": [
                {"link": "base", "xyz": [0.0, 0.03, 0.02]},
                {"link": "hand", "xyz": [0.02, 0.01, 0.03]},
            ],
            "gain": 45.0,
            "bias": 0.5,
        },
    ],
    "markers": [
        {"name": "m_l0", "link": "l0", "xyz": [0.03, 0.02, 0.01]},
        {"name": "m_arm", "link": "arm", "xyz": [0.1, 0.01, 0.02]},
        {"name": "m_hand", "link": "hand", "xyz": [0.04, -0.02, 0.01]},
    ],
    "chambers": [
        {
            "name": "j2.flex",
            "joint": "j2",
            "volume_sensor": "j2_pot",
            "supply": 620.0,
            "room": 100.0,
        }
    ],
}


@pytest.fixture(scope="session")
def bundled():
    """Loaded bundled robots by name (loaded once per session)."""
    cache = {}

    def get(name: str):
        if name not in cache:
            cache[name] = load_robot(BUNDLED_ROBOTS / name)
        return cache[name]

    return get


@pytest.fixture
def tiny_sensors():
    """A fresh deep copy of the tiny robot's sensors.yaml content, free to mutate."""
    return copy.deepcopy(TINY_SENSORS)


@pytest.fixture
def tiny_urdf():
    return TINY_URDF


@pytest.fixture
def robot_dir(tmp_path):
    """Write a robot directory (sensors mapping, URDF text) under tmp_path; returns its path."""

    def make(sensors, urdf: str = TINY_URDF, name: str = "tiny"):
        directory = tmp_path / name
        write_text(directory / "robot.urdf", urdf)
        save_yaml(sensors, directory / "sensors.yaml")
        return directory

    return make


@pytest.fixture(scope="session")
def tiny_robot(tmp_path_factory):
    directory = tmp_path_factory.mktemp("tiny")
    write_text(directory / "robot.urdf", TINY_URDF)
    save_yaml(TINY_SENSORS, directory / "sensors.yaml")
    # j0 moves no sensor relative to the base: load_robot locks it unless the data use it (as
    # here, so that the moving-base kinematics keep a joint upstream of the base)
    return load_robot(directory, joints=("j0",))


def random_q(robot, rng: np.random.Generator, n: int, margin: float = 1e-3) -> np.ndarray:
    """(n, n_joints) configurations drawn uniformly inside the joint limits."""
    return rng.uniform(robot.lower + margin, robot.upper - margin, size=(n, robot.n_joints))


@pytest.fixture
def sample_q():
    return random_q
