"""A small arm with rotary pots and an encoder, as the Unitree Z1 of the user trial (five rotary pots,
an encoder on the last joint): the shoulder turns every marker about an axis fixed in the base (a
root gauge), the wrist's markers all ride on the hand (a leaf gauge read by the encoder). Its
sessions come from the simulator with explicit seeds."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from diegocal.io import Log, save_log, save_yaml, write_text
from diegocal.robot import load_robot
from diegocal.sim.kinematics import KinematicsOptions, simulate_kinematics

INERTIAL = '<inertial><mass value="1"/><inertia ixx="1e-3" iyy="1e-3" izz="1e-3" ixy="0" ixz="0" iyz="0"/></inertial>'
URDF = f"""<?xml version="1.0"?>
<robot name="encoder_arm">
  <link name="base">{INERTIAL}</link><link name="upper">{INERTIAL}</link>
  <link name="fore">{INERTIAL}</link><link name="hand">{INERTIAL}</link>
  <joint name="shoulder" type="revolute"><parent link="base"/><child link="upper"/>
    <axis xyz="0 0 1"/><limit lower="-1.5" upper="1.5" effort="1" velocity="1"/></joint>
  <joint name="elbow" type="revolute"><parent link="upper"/><child link="fore"/><origin xyz="0.3 0 0"/>
    <axis xyz="0 1 0"/><limit lower="-1.5" upper="1.5" effort="1" velocity="1"/></joint>
  <joint name="wrist" type="revolute"><parent link="fore"/><child link="hand"/><origin xyz="0.25 0 0"/>
    <axis xyz="1 0 0"/><limit lower="-1.5" upper="1.5" effort="1" velocity="1"/></joint>
</robot>
"""
SENSORS = {
    "urdf": "robot.urdf",
    "base_link": "base",
    "pots": [
        {"name": "shoulder", "kind": "rotary", "joint": "shoulder", "gain": 1.0, "bias": 2.5},
        {"name": "elbow", "kind": "rotary", "joint": "elbow", "gain": 1.0, "bias": 2.5},
        {"name": "wrist", "kind": "encoder", "joint": "wrist", "bias": 0.0},
    ],
    "markers": [
        {"name": "u1", "link": "upper", "xyz": [0.1, 0.03, 0.0]},
        {"name": "u2", "link": "upper", "xyz": [0.2, -0.03, 0.02]},
        {"name": "f1", "link": "fore", "xyz": [0.1, 0.0, 0.04]},
        {"name": "f2", "link": "fore", "xyz": [0.2, 0.03, -0.02]},
        {"name": "h1", "link": "hand", "xyz": [0.05, 0.06, 0.0]},
        {"name": "h2", "link": "hand", "xyz": [0.08, 0.0, -0.05]},
        {"name": "h3", "link": "hand", "xyz": [0.1, -0.04, 0.04]},
    ],
    "chambers": [],
}


def make_robot(directory: Path) -> Path:
    """Write the arm's robot.urdf and sensors.yaml into ``directory``; return it."""
    directory.mkdir(parents=True, exist_ok=True)
    write_text(directory / "robot.urdf", URDF)
    save_yaml(SENSORS, directory / "sensors.yaml")
    return directory


def session(robot_dir: Path, seed: int, duration: float = 8.0, occlusion: float = 0.1, robot_seed: int = 1) -> Log:
    """A simulated session of the arm (pot noise 3 mV on the rotary pots, 3 mrad on the encoder), its
    motion and noise drawn with ``seed``, its calibration and mocap frame with ``robot_seed``."""
    options = KinematicsOptions(
        duration=duration, rate_hz=50.0, occlusion=occlusion, pot_noise=0.003, robot_seed=robot_seed
    )
    log = simulate_kinematics(load_robot(robot_dir), options, np.random.default_rng(seed))
    return log


def save_session(robot_dir: Path, path: Path, seed: int, **kwargs) -> Path:
    save_log(session(robot_dir, seed, **kwargs), path)
    return path
