"""Fixtures for the SGP tests: tiny robots written from strings and a seeded torque simulator.

The simulator here is deliberately minimal and independent of diegocal.sim (tau = pinocchio.rnea
+ viscous + Coulomb friction + an optional position-dependent friction bump + white noise), so
these tests check the estimators against a ground truth they do not share code with.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from diegocal.io import Log, make_stream
from diegocal.robot import load_robot

ARM2_URDF = """<?xml version="1.0"?>
<robot name="arm2">
  <link name="base"/>
  <link name="upper"><inertial><origin xyz="0.15 0 0.01"/><mass value="1.2"/>
    <inertia ixx="0.002" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.011"/></inertial></link>
  <link name="fore"><inertial><origin xyz="0.12 0.01 0"/><mass value="0.7"/>
    <inertia ixx="0.001" ixy="0" ixz="0" iyy="0.004" iyz="0" izz="0.0045"/></inertial></link>
  <joint name="shoulder" type="revolute"><parent link="base"/><child link="upper"/>
    <axis xyz="0 1 0"/><limit lower="-2.5" upper="2.5" effort="50" velocity="10"/></joint>
  <joint name="elbow" type="revolute"><parent link="upper"/><child link="fore"/>
    <origin xyz="0.3 0 0"/><axis xyz="0 1 0"/>
    <limit lower="-2.0" upper="2.0" effort="50" velocity="10"/></joint>
</robot>
"""

PENDULUM_URDF = """<?xml version="1.0"?>
<robot name="pend">
  <link name="base"/>
  <link name="bob"><inertial><origin xyz="0 0 -0.5"/><mass value="1.0"/>
    <inertia ixx="0.001" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.001"/></inertial></link>
  <joint name="theta" type="revolute"><parent link="base"/><child link="bob"/>
    <axis xyz="0 1 0"/><limit lower="-3.2" upper="3.2" effort="50" velocity="10"/></joint>
</robot>
"""

SENSORS = "urdf: robot.urdf\nbase_link: base\npots: []\nmarkers: []\nchambers: []\n"

FRICTION = {"viscous": np.array([0.3, 0.2]), "coulomb": np.array([0.15, 0.1])}


def write_robot(directory, urdf: str):
    directory.mkdir(parents=True, exist_ok=True)
    (directory / "robot.urdf").write_text(urdf)
    (directory / "sensors.yaml").write_text(SENSORS)
    return directory


@pytest.fixture(scope="session")
def friction():
    return FRICTION


@pytest.fixture(scope="session")
def arm2_dir(tmp_path_factory):
    return write_robot(tmp_path_factory.mktemp("arm2"), ARM2_URDF)


@pytest.fixture(scope="session")
def arm2(arm2_dir):
    return load_robot(arm2_dir)


@pytest.fixture(scope="session")
def pendulum(tmp_path_factory):
    return load_robot(write_robot(tmp_path_factory.mktemp("pend"), PENDULUM_URDF))


def excitation(robot, T: int, rate: float, rng, scale: float = 0.35):
    """Sum of three sinusoids per joint inside the limits: q, qd, qdd of shape (T, n)."""
    n = robot.n_joints
    t = np.arange(T) / rate
    q, qd, qdd = (np.zeros((T, n)) for _ in range(3))
    for j in range(n):
        mid, amp = (
            0.5 * (robot.lower[j] + robot.upper[j]),
            scale * (robot.upper[j] - robot.lower[j]),
        )
        for _ in range(3):
            w = 2 * np.pi * rng.uniform(0.1, 0.7)
            ph, a = rng.uniform(0, 2 * np.pi), amp / 3
            q[:, j] += a * np.sin(w * t + ph)
            qd[:, j] += a * w * np.cos(w * t + ph)
            qdd[:, j] -= a * w * w * np.sin(w * t + ph)
        q[:, j] += mid
    return t, q, qd, qdd


def true_torque(robot, q, qd, qdd, friction=FRICTION, bump=None):
    """rnea + viscous + Coulomb friction (+ bump: (joint, low, high, N·m·s/rad) extra viscous)."""
    n = robot.n_joints
    tau = np.array([pin.rnea(robot.model, robot.data, q[i], qd[i], qdd[i]) for i in range(len(q))])
    tau += friction["viscous"][:n] * qd + friction["coulomb"][:n] * np.sign(qd)
    if bump is not None:
        j, lo, hi, c = bump
        inside = (q[:, j] > lo) & (q[:, j] < hi)
        tau[:, j] += c * qd[:, j] * inside
    return tau


def make_log(robot, q, qd, qdd, tau, t=None):
    names = robot.joint_names
    t = np.arange(len(q)) * 0.01 if t is None else t
    streams = {
        k: make_stream(names, v) for k, v in (("q", q), ("qd", qd), ("qdd", qdd), ("tau", tau))
    }
    return Log(t, streams, robot=robot.name)


@pytest.fixture(scope="session")
def simulate():
    """simulate(robot, T, seed, noise=0.05, bump=None) -> (log, clean torque (T, n))."""

    def run(robot, T=300, seed=0, noise=0.05, bump=None, rate=50.0):
        rng = np.random.default_rng(seed)
        t, q, qd, qdd = excitation(robot, T, rate, rng)
        clean = true_torque(robot, q, qd, qdd, bump=bump)
        tau = clean + noise * rng.standard_normal(clean.shape)
        return make_log(robot, q, qd, qdd, tau, t), clean

    return run
