"""Guard.joint_region on issue #14's arm at 600 samples (slow): a 6-s run (``diegocal simulate
dynamics --robot arm3 --effect position_friction:joint3 --duration 6 --seed 11``), tested on 40 s
of seed 12's trajectory of the same robot. Without the joint cut (``--no-joint-region``) the joint
SE GP carries the friction's step below its onset (joint 3 covered at about 0.8 within ±2σ); the
joint GP cut at the two stages' onset (the default) must win the guard's choice, predict joint 3
at under a third of the uncut model's nMSE, cover every joint within 0.85-0.99, and come back from
a saved model unchanged.
"""

from dataclasses import replace

import numpy as np
import pytest

from diegocal.robot import BUNDLED_ROBOTS, load_robot
from diegocal.sgp import SGPOptions, fit_dynamics, load_model
from diegocal.sgp.model import default_guard
from diegocal.sgp.store import save_model
from diegocal.sim.dynamics import DynamicsOptions, simulate_dynamics
from diegocal.sim.effects import parse_effects
from experiments.sgp.common import same_robot

pytestmark = pytest.mark.slow


def _simulate(robot, seed: int, duration: float, friction=None):
    opts = DynamicsOptions(
        duration=duration, effects=parse_effects(["position_friction:joint3"]), **(friction or {})
    )
    return simulate_dynamics(robot, opts, np.random.default_rng(seed))


def test_a_joint_gp_cut_at_the_onset_mends_a_short_runs_joint3(tmp_path):
    robot = load_robot(BUNDLED_ROBOTS / "arm3")
    train = _simulate(robot, 11, 6.0)
    test = _simulate(robot, 12, 40.0, friction=same_robot(train, robot))
    tau = test.stream("tau").data
    guard = replace(default_guard(("viscous", "coulomb")), joint_region=False)
    options = {"uncut": SGPOptions(guard_options=guard), "cut": SGPOptions()}
    models = {k: fit_dynamics(train, robot, o) for k, o in options.items()}
    pred = {k: m.predict(test) for k, m in models.items()}
    nmse = {k: np.mean((tau - p.tau) ** 2, axis=0) / tau.var(axis=0) for k, p in pred.items()}
    cover = np.mean(np.abs(tau - pred["cut"].tau) <= 2 * pred["cut"].tau_std, axis=0)
    joint3 = models["cut"].hyperparameters_["joint3"]
    assert joint3["guard_choice"] == "cut"
    assert abs(joint3["region"]["onset"] - 1.78) < 0.01  # the friction's onset (rad)
    assert nmse["cut"][2] < nmse["uncut"][2] / 3, nmse
    assert np.all(nmse["cut"][:2] <= nmse["uncut"][:2] * 1.05), nmse
    assert np.all((cover >= 0.85) & (cover <= 0.99)), cover
    save_model(models["cut"], tmp_path / "cut.sgp")
    back = load_model(tmp_path / "cut.sgp").predict(test)
    np.testing.assert_allclose(back.tau, pred["cut"].tau, rtol=1e-9, atol=1e-9)
