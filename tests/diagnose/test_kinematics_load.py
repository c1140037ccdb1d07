"""A pot read through a belt that stretches under its joint's load (issue #31): the reading's
error follows the gravity torque on the joint, no cause of the vocabulary. A sensor nonlinearity
(u², u³ of the pot's own reading) takes up the part that follows the joint's own angle and was
named; the pot's load curve (:mod:`diegocal.diagnose.kinematics_curves`) explains more, so the
pot is ``unexplained``."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pinocchio as pin

from diegocal.diagnose import DiagnoseOptions, diagnose
from diegocal.io import make_stream
from diegocal.robot import load_robot
from diegocal.sim.kinematics import KinematicsOptions, simulate_kinematics


def stretched(robot, seed: int, pot: str, share: float, duration: float):
    """A clean log of ``robot`` whose ``pot`` reads its joint's angle plus ``share`` × (its gravity
    torque / the largest) × (the angle − its mean): the form of a user trial's belt stretch."""
    log = simulate_kinematics(robot, KinematicsOptions(duration=duration), np.random.default_rng(seed))
    q = log.truth.signals["q"].data
    names = list(log.streams["pots"].names)
    k = robot.joint_index(next(p.joint for p in robot.sensors.pots if p.name == pot))
    data = robot.model.createData()
    g = np.array([pin.computeGeneralizedGravity(robot.model, data, qq)[k] for qq in q])
    gain = next(
        b["parameters"]["gain"]["value"]
        for b in log.truth.params["baseline"]
        if b["cause"] == "pot_transfer" and b["channel"] == pot
    )
    p = log.streams["pots"].data.copy()
    p[:, names.index(pot)] += gain * share * g / np.abs(g).max() * (q[:, k] - q[:, k].mean())
    return replace(log, streams={**log.streams, "pots": make_stream(names, p)})


def test_a_belt_stretched_by_the_load_is_no_sensor_nonlinearity(tmp_path):
    """UR5 of experiments/kinematics_generator.py, 10 s, shoulder_lift's belt stretched 5 %:
    named ``sensor_nonlinearity`` without the load curve."""
    from experiments.kinematics_generator import robot_dir

    robot = load_robot(robot_dir(tmp_path, "ur5"))
    log = stretched(robot, 2, "shoulder_lift_joint_pot", 0.05, 10.0)
    d = diagnose(log, robot, DiagnoseOptions(domain="kinematics"))
    found = [(f.cause, f.channel) for f in d.findings]
    assert ("unexplained", "shoulder_lift_joint_pot") in found
    assert all(cause == "unexplained" for cause, _ in found)
