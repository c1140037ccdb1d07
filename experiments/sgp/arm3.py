"""Simulated 3-link arm (thesis §3.4.4, eq. 3.29-3.30, Fig. 3.8-3.9).

True dynamics: rigid body + viscous + Coulomb friction (eq. 3.29) + cable-like friction on joint 3
as it approaches its upper limit (``position_friction``, q₃ ≥ 1.35 rad). The parametric part is
eq. 3.30's full linear-in-parameter model (rigid body + viscous + Coulomb). Train on a horizontal
figure-eight; test on a similar horizontal one (new seed: centre, size and period jittered) and on
a vertical one (generalisation to unseen states), both of the same robot (the training run's
friction; before issue #14 each test log drew its own).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from diegocal.robot import load_robot
from diegocal.robot.model import BUNDLED_ROBOTS
from diegocal.sgp import SGPOptions
from diegocal.sim.dynamics import DynamicsOptions, simulate_dynamics
from experiments.sgp.common import run_methods, same_robot

CABLE = (1.35, 2.3)


@dataclass(frozen=True)
class ArmConfig:
    train_s: float = 10.0
    test_s: float = 6.0
    rate_hz: float = 20.0
    noise: float = 0.01
    cable: float = 2.0
    sgp: SGPOptions = SGPOptions(friction=("viscous", "coulomb"))


def arm_data(robot, seed: int, cfg: ArmConfig):
    """Training log and test logs of one robot: the tests keep the training run's friction."""
    rng = np.random.default_rng(seed)

    def sim(trajectory, duration, friction=None):
        opts = DynamicsOptions(
            trajectory=trajectory,
            duration=duration,
            rate_hz=cfg.rate_hz,
            effects=("position_friction:joint3",),
            regions={"joint3": CABLE},
            effect_scale=cfg.cable,
            noise=cfg.noise,
            **(friction or {}),
        )
        return simulate_dynamics(robot, opts, rng)

    train = sim("figure8-horizontal", cfg.train_s)
    same = same_robot(train, robot)
    tests = {
        "horizontal": sim("figure8-horizontal", cfg.test_s, same),
        "vertical": sim("figure8-vertical", cfg.test_s, same),
    }
    return train, tests


def run_arm3(seeds=(0, 1, 2, 3, 4), cfg: ArmConfig = ArmConfig(), methods=None) -> list:
    robot = load_robot(BUNDLED_ROBOTS / "arm3")
    out = []
    for seed in seeds:
        train, tests = arm_data(robot, seed, cfg)
        tests = {k: (v, {"all": np.ones(v.n_samples, bool)}) for k, v in tests.items()}
        out += run_methods(train, tests, robot, cfg.sgp, "arm3", seed, methods)
    return out
