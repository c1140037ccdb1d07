"""Reduced versions of the thesis's SGP experiments (full ones: bench/bench_sgp_experiments.py).

Each checks a claim of thesis §3.4 against simulator ground truth, at a size that keeps the fits
to seconds: the parameters (not just "it ran") and held-out errors in the named regions.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from diegocal.robot import load_robot
from diegocal.robot.model import BUNDLED_ROBOTS
from diegocal.sgp import SGPOptions, fit_dynamics, true_parameters
from experiments.sgp.common import score
from experiments.sgp.pendulum import PendulumConfig, pendulum_data
from experiments.sgp.reaction_wheel import (
    ForwardModel,
    WheelConfig,
    forward_arrays,
    predictable_acceleration,
    wheel_data,
)
from experiments.sgp.reaction_wheel import true_parameters as wheel_parameters

QUICK = dict(maxiter=40, hyper_max=200)


def test_pendulum_sgp_explains_away_the_friction_bump():
    """§3.4.1: the bump biases PR's parameters; SGP's GP part absorbs it, so its parameters are
    closer to the truth and the bump region is predicted well (dense data there)."""
    robot = load_robot(BUNDLED_ROBOTS / "pendulum")
    cfg = PendulumConfig(train_s=8.0, test_s=6.0, sgp=SGPOptions(friction=(), **QUICK))
    train, test, regions = pendulum_data(robot, 0, cfg)
    pr = fit_dynamics(train, robot, replace(cfg.sgp, kind="pr"))
    sgp = fit_dynamics(train, robot, replace(cfg.sgp, kind="sgp"))
    w_true = sgp.base_.from_full(true_parameters(robot, friction=()))
    err_pr = np.linalg.norm(pr.parametric_.values - w_true)
    err_sgp = np.linalg.norm(sgp.parametric_.values - w_true)
    assert err_sgp < err_pr
    cells = {}
    for name, model in (("pr", pr), ("sgp", sgp)):
        for s in score(model.predict(test), test, regions, "pendulum", 0, name, "whirl"):
            cells[(name, s.region)] = s
    assert cells[("sgp", "bump [2,2.5]")].nmse < 0.2 * cells[("pr", "bump [2,2.5]")].nmse
    assert cells[("sgp", "dense")].nmse < cells[("pr", "dense")].nmse
    print({k: (round(c.nmse, 4), round(c.coverage, 2)) for k, c in cells.items()})


@pytest.mark.slow
def test_reaction_wheel_sgp_explains_away_the_missing_friction():
    """§3.4.2, eq. 3.28: the 6-parameter forward model omits viscous friction. PR's motor gain of
    the wheel axis absorbs the friction (biased); the SGP's GP takes the friction, so its gain is
    closer to the true M⁻¹ entry, and on pole-down test data (dense) it beats PR on both axes."""
    robot = load_robot(BUNDLED_ROBOTS / "reaction_wheel")
    cfg = WheelConfig(train_s=8.0, test_s=3.0)
    train, tests = wheel_data(robot, 0, cfg)
    U, Y, F = forward_arrays(train.without_truth())
    down = tests["pole-down"]
    Ut, _, Ft = forward_arrays(down)
    clean = predictable_acceleration(down, robot)
    w_true = wheel_parameters(robot)
    err, gain = {}, {}
    for method in ("PR", "SGP"):
        model = ForwardModel(method, seed=0, maxiter=cfg.maxiter).fit(U, Y, F)
        mean, _ = model.predict(Ut, Ft)
        err[method] = np.mean((mean - clean) ** 2, axis=0) / np.var(clean, axis=0)
        gain[method] = abs(model.w_[5] - w_true[5]) / w_true[5]
    print(err, gain)
    assert (err["SGP"] < err["PR"]).all()
    assert gain["PR"] > 0.01  # the omitted friction matters: PR's motor gain is visibly off
    assert gain["SGP"] < 0.5 * gain["PR"]
