"""The two-stage GP's amplitude above a cut kernel's onset is capped by the residual there
(:func:`diegocal.sgp.guard.capped_above`). Issue #14's arm at 200 samples (4 s at 50 Hz), the
hidden friction on joint 3 above 1.78 rad, training run 38 (``bench/bench_sgp_sizes.py --sizes 200
--seeds 21-40``), tested on 2,000 samples of another trajectory of the same robot whose joint-3
velocity leaves the training range: uncapped, ML-II put the side above the onset at 2.15 N·m,
28 times PR's residual there, and the two stages erred 8.7 times PR's nMSE on joint 3."""

import numpy as np
import pytest

import diegocal.sgp.guard as guard
from diegocal.robot import BUNDLED_ROBOTS, load_robot
from diegocal.sgp import SGPOptions, fit_dynamics
from experiments.sgp.common import friction_case, same_robot


@pytest.fixture(scope="module")
def run38():
    arm3 = load_robot(BUNDLED_ROBOTS / "arm3")
    train = friction_case(arm3, 200, 38).slice(0, 200)
    test = friction_case(arm3, 2000, 1038, same_robot(train, arm3)).slice(0, 2000)
    tau = test.stream("tau").select(arm3.joint_names).data
    pr = fit_dynamics(train, arm3, SGPOptions(kind="pr"))

    def nmse(model):
        return np.mean((model.predict(test).tau - tau) ** 2, axis=0) / tau.var(axis=0)

    return arm3, train, nmse, nmse(pr)


def test_capped_the_two_stages_are_no_worse_than_pr(run38):
    arm3, train, nmse, pr = run38
    sgp = fit_dynamics(train, arm3, SGPOptions())
    assert sgp.hyperparameters_["joint3"]["guard_choice"] == "two-stage"
    assert nmse(sgp)[2] <= 1.05 * pr[2], (nmse(sgp), pr)


def test_uncapped_they_err_several_times_pr(run38, monkeypatch):
    """The check above can fail: without the cap the same fit errs > 5× PR's on joint 3."""
    arm3, train, nmse, pr = run38
    monkeypatch.setattr(guard, "MAX_AMPLITUDE_ABOVE", np.inf)
    sgp = fit_dynamics(train, arm3, SGPOptions())
    assert nmse(sgp)[2] > 5.0 * pr[2], (nmse(sgp), pr)
