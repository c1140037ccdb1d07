"""Simulated reaction wheel (thesis §3.4.2, eq. 3.27-3.28, Fig. 3.4-3.5, §3.5.1).

True dynamics: rigid body + viscous friction on both axes (eq. 3.27's 10 parameters); the fitted
parametric part omits friction (eq. 3.28's 6 parameters → ``SGPOptions(friction=())``). Training:
``pole-down`` (multi-sine motor torque of random frequencies; the thesis used 1000 steps at
100 Hz, we simulate at 100 Hz and keep every 2nd sample of 4 s, 200 samples, so that the whole
bench runs in the time a shared 2-core machine allows). Tests: another ``pole-down`` log (dense
training data) and a ``pole-up`` log balanced by
LQR on the true linearised dynamics (sparse: far from every training sample).

The thesis predicts accelerations (forward dynamics); diegocal's models predict torques (inverse
dynamics), so the pole's target is the random disturbance torque acting on it (the process noise
that makes the thesis's balanced wheel "wander") and the wheel's is the motor torque.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from diegocal.robot import load_robot
from diegocal.robot.model import BUNDLED_ROBOTS
from diegocal.sgp import SGPOptions
from diegocal.sgp_experiments.common import run_methods, select
from diegocal.sim.dynamics import DynamicsOptions, simulate_dynamics


@dataclass(frozen=True)
class WheelConfig:
    train_s: float = 4.0
    test_s: float = 4.0
    rate_hz: float = 100.0
    decimate: int = 2
    noise: float = 0.002
    sgp: SGPOptions = SGPOptions(friction=(), maxiter=60)


def wheel_data(robot, seed: int, cfg: WheelConfig):
    """Training (pole-down) and the two test logs, from one seed."""
    rng = np.random.default_rng(seed)

    def sim(trajectory, duration):
        opts = DynamicsOptions(
            trajectory=trajectory,
            duration=duration,
            rate_hz=cfg.rate_hz,
            coulomb=0.0,
            noise=cfg.noise,
        )
        log = simulate_dynamics(robot, opts, rng)
        return select(log, np.arange(log.n_samples) % cfg.decimate == 0)

    train = sim("pole-down", cfg.train_s)
    return train, {"pole-down": sim("pole-down", cfg.test_s), "pole-up": sim("pole-up", cfg.test_s)}


def run_reaction_wheel(
    seeds=(0, 1, 2, 3, 4), cfg: WheelConfig = WheelConfig(), methods=None
) -> list:
    robot = load_robot(BUNDLED_ROBOTS / "reaction_wheel")
    out = []
    for seed in seeds:
        train, tests = wheel_data(robot, seed, cfg)
        tests = {k: (v, {"all": np.ones(v.n_samples, bool)}) for k, v in tests.items()}
        out += run_methods(train, tests, robot, cfg.sgp, "reaction_wheel", seed, methods)
    return out
