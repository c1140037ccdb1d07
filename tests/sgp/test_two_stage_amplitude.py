"""The two-stage GP's amplitude above a cut kernel's onset is capped by the residual there
(:func:`diegocal.sgp.guard_options.capped_above`). Issue #14's arm at 200 samples (4 s at 50 Hz), the
hidden friction on joint 3 above 1.78 rad, training run 38 (``bench/bench_sgp_sizes.py --sizes 200
--seeds 21-40``), tested on 2,000 samples of another trajectory of the same robot whose joint-3
velocity leaves the training range: uncapped, ML-II put the side above the onset at 2.15 N·m,
28 times PR's residual there, and the two stages erred 8.7 times PR's nMSE on joint 3."""

import numpy as np
import pytest

import diegocal.sgp.guard_options as guard
from diegocal.sgp import SGPOptions, fit_dynamics

from .friction_runs import held_out_run


@pytest.fixture(scope="module")
def run38():
    return held_out_run(38)


def test_capped_the_two_stages_are_no_worse_than_pr(run38):
    sgp = fit_dynamics(run38.train, run38.arm3, SGPOptions())
    assert sgp.hyperparameters_["joint3"]["guard_choice"] == "two-stage"
    assert run38.nmse(sgp)[2] <= 1.05 * run38.pr[2], (run38.nmse(sgp), run38.pr)


def test_uncapped_they_err_several_times_pr(run38, monkeypatch):
    """The check above can fail: without the cap the same fit errs > 5× PR's on joint 3."""
    monkeypatch.setattr(guard, "MAX_AMPLITUDE_ABOVE", np.inf)
    sgp = fit_dynamics(run38.train, run38.arm3, SGPOptions())
    assert run38.nmse(sgp)[2] > 5.0 * run38.pr[2], (run38.nmse(sgp), run38.pr)
