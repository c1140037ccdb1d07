"""Pendulum with a friction irregularity (thesis §3.1.1, §3.4.1, Fig. 3.1-3.2).

The true pendulum has no friction except a strong position-dependent one for θ ∈ [2, 2.5] rad
(``position_friction``); the parametric model is the frictionless rigid body (θ̈ = w sin θ in the
thesis's forward form; here its inverse-dynamics regressor, ``friction=()``). The pendulum is
driven round and round (``whirl``), so the irregularity acts in one direction and biases a
parametric fit. Training data are dense everywhere except θ ∈ [−2, 0], kept at ``sparse_keep``
(Fig. 3.2's data-sparse region). Regions scored on a held-out log: ``sparse [-2,0]``,
``bump [2,2.5]``, ``dense`` (the rest).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from diegocal.robot import load_robot
from diegocal.robot.model import BUNDLED_ROBOTS
from diegocal.sgp import SGPOptions
from diegocal.sim.dynamics import DynamicsOptions, simulate_dynamics
from experiments.sgp.common import run_methods, select

SPARSE = (-2.0, 0.0)
BUMP = (2.0, 2.5)


@dataclass(frozen=True)
class PendulumConfig:
    """Sizes and levels. ``train_s``/``test_s`` s at ``rate_hz``; ``noise`` N·m; ``bump`` scales
    the irregularity (1 = the simulator's default, 0.3 × RMS torque)."""

    train_s: float = 10.0
    test_s: float = 8.0
    rate_hz: float = 25.0
    sparse_keep: float = 0.05
    bump: float = 3.0
    noise: float = 0.02
    sgp: SGPOptions = SGPOptions(friction=())


def pendulum_data(robot, seed: int, cfg: PendulumConfig):
    """Training log (sparse in [−2, 0]) and test log with region masks."""
    opts = DynamicsOptions(
        trajectory="whirl",
        effects=("position_friction:theta",),
        viscous=0.0,
        coulomb=0.0,
        noise=cfg.noise,
        effect_scale=cfg.bump,
        regions={"theta": BUMP},
        rate_hz=cfg.rate_hz,
    )
    rng = np.random.default_rng(seed)
    full = simulate_dynamics(robot, replace(opts, duration=cfg.train_s), rng)
    test = simulate_dynamics(robot, replace(opts, duration=cfg.test_s), rng)
    q = full.streams["q"].data[:, 0]
    in_sparse = (q > SPARSE[0]) & (q < SPARSE[1])
    train = select(full, ~in_sparse | (rng.random(q.size) < cfg.sparse_keep))
    qt = test.streams["q"].data[:, 0]
    sparse = (qt > SPARSE[0]) & (qt < SPARSE[1])
    bump = (qt >= BUMP[0]) & (qt <= BUMP[1])
    regions = {"sparse [-2,0]": sparse, "bump [2,2.5]": bump, "dense": ~(sparse | bump)}
    return train, test, regions


def run_pendulum(seeds=(0, 1, 2, 3, 4), cfg: PendulumConfig = PendulumConfig(), methods=None) -> list:
    """Scores of every method and seed (list of :class:`~experiments.sgp.common.Score`)."""
    robot = load_robot(BUNDLED_ROBOTS / "pendulum")
    out = []
    for seed in seeds:
        train, test, regions = pendulum_data(robot, seed, cfg)
        out += run_methods(train, {"whirl": (test, regions)}, robot, cfg.sgp, "pendulum", seed, methods)
    return out
