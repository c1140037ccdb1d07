"""Fixtures of the pneumatic tests: a tiny two-joint robot with four chambers, and seeded logs."""

from __future__ import annotations

import numpy as np
import pytest

from diegocal.robot import load_robot
from diegocal.sim.pneumatics import PneumaticSimOptions, simulate_pneumatics

URDF = """<?xml version="1.0"?>
<robot name="tiny_pneu">
  <link name="base"/>
  <link name="upper"><inertial><mass value="1"/><inertia ixx="0.01" iyy="0.01" izz="0.01"
    ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="lower"><inertial><mass value="1"/><inertia ixx="0.01" iyy="0.01" izz="0.01"
    ixy="0" ixz="0" iyz="0"/></inertial></link>
  <joint name="shoulder" type="revolute"><parent link="base"/><child link="upper"/>
    <axis xyz="0 1 0"/><limit lower="-1.0" upper="1.2" effort="10" velocity="10"/></joint>
  <joint name="elbow" type="revolute"><parent link="upper"/><child link="lower"/>
    <origin xyz="0 0 -0.3"/><axis xyz="0 1 0"/>
    <limit lower="0" upper="2.0" effort="10" velocity="10"/>
  </joint>
</robot>
"""

# shoulder chambers carry the full geometry; the elbow's use the simulator's defaults.
SENSORS = """urdf: robot.urdf
base_link: base
pots:
  - {name: shoulder_pot, kind: rotary, joint: shoulder, gain: 1.2, bias: 2.5}
  - {name: elbow_pot, kind: rotary, joint: elbow, gain: 0.8, bias: 1.0}
chambers:
  - {name: shoulder.flex, joint: shoulder, volume_sensor: shoulder_pot, supply: 620.0, room: 100.0,
     side: 1, bore_area: 0.0003142, moment_arm: 0.015, dead_volume: 5.0e-06, stroke: 0.03}
  - {name: shoulder.ext, joint: shoulder, volume_sensor: shoulder_pot, supply: 620.0, room: 100.0,
     side: -1, bore_area: 0.0003142, moment_arm: 0.015, dead_volume: 5.0e-06, stroke: 0.03}
  - {name: elbow.flex, joint: elbow, volume_sensor: elbow_pot, supply: 620.0, room: 100.0}
  - {name: elbow.ext, joint: elbow, volume_sensor: elbow_pot, supply: 620.0, room: 100.0}
"""


def write_robot(directory, sensors: str = SENSORS):
    directory.mkdir(parents=True, exist_ok=True)
    (directory / "robot.urdf").write_text(URDF)
    (directory / "sensors.yaml").write_text(sensors)
    return directory


@pytest.fixture(scope="session")
def robot_dir(tmp_path_factory):
    return write_robot(tmp_path_factory.mktemp("tiny_pneu"))


@pytest.fixture(scope="session")
def robot(robot_dir):
    return load_robot(robot_dir)


SESSION_S = 15.0


@pytest.fixture(scope="session")
def physics_log(robot):
    """Five independent 15-s sessions of thin-plate physics, simulated together (vectorised).

    10 sub-steps per tick: the exponential-midpoint error is then ~0.15 kPa RMS (test_sim checks
    20 vs 40); plenty for fitting tests and 2x cheaper.
    """
    return simulate_pneumatics(
        robot, PneumaticSimOptions(duration=SESSION_S, sessions=5, substeps=10, seed=11)
    )


def _split(log):
    n = int(round(SESSION_S * log.rate_hz)) + 1  # samples per session
    return log.slice(0, 4 * n), log.slice(4 * n, log.n_samples)


@pytest.fixture(scope="session")
def train_log(physics_log):
    """Sessions 1-4 (6000 samples per chamber) for fitting."""
    return _split(physics_log)[0]


@pytest.fixture(scope="session")
def test_log(physics_log):
    """Session 5: held-out data (same robot and valves, other motion and commands)."""
    return _split(physics_log)[1]


@pytest.fixture()
def rng():
    return np.random.default_rng(0)
