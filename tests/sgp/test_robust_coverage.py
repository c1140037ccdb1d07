"""W's cluster-robust variance (:func:`diegocal.sgp.gp.robust_w_cov`) on the size of the thesis's
experiments: arm3, 200 samples at 50 Hz (4 s), the hidden friction on joint 3 above 1.78 rad left
out of the model, tested on 2,000 samples of another trajectory of the same robot (the scale
bench's case, ``bench/bench_sgp_sizes.py --sizes 200``). Training runs 4 and 5 are the two of 10
whose friction biased W most: eq. (3.20)'s variance alone covered joint 2's held-out torque
0.76 and 0.63 of the time under PR, and 0.58 under the SGP of run 5."""

import numpy as np
import pytest

from diegocal.evaluate import score
from diegocal.sgp import SGPOptions, fit_dynamics
from diegocal.sgp.gp import parametric_robust_w_cov

from .friction_runs import held_out_run


def _coverage(model, log):
    pred = model.predict(log)
    return score(
        log.stream("tau").select(model.joint_names).data, pred.tau, model.joint_names, std=pred.tau_std
    ).coverage


def _without_robust(model):
    for post in (model.gp_.posterior_, getattr(model.gp_, "pr_posterior_", None)):
        if post is not None:
            post.w_cov_robust = None
    return model


@pytest.mark.parametrize("kind, seed", [("pr", 4), ("pr", 5), ("sgp", 5)])
def test_a_bias_the_friction_puts_in_w_is_inside_the_two_sigma_band(kind, seed):
    run = held_out_run(seed)
    test = run.test
    model = fit_dynamics(run.train, run.arm3, SGPOptions(kind=kind))
    cov = _coverage(model, test)
    assert np.all((cov[:2] >= 0.85) & (cov[:2] <= 0.99)), f"{kind} run {seed}: ±2σ coverage {cov}"  # joints 1-2
    plain = _coverage(_without_robust(model), test)  # eq. (3.20) alone: the check can fail
    assert plain[1] < 0.85, plain


@pytest.mark.slow
def test_two_stages_take_w_s_robust_variance_from_what_both_leave():
    """Run 8 at 500 samples: the guard gives joint 3 two stages, whose GP takes up the friction
    PR leaves; W's robust variance from PR's own residual everywhere would count that bias again
    where the GP has data (the band held 1.00 of joint 3's held-out torque). From what both
    stages leave there (PR's own beyond the GP's data) it holds 0.991 (0.97 with what both
    leave everywhere, round 11's band, which held run 58 at 200 samples only 0.84: below)."""
    run = held_out_run(8, n=500)
    arm3, train, test = run.arm3, run.train, run.test
    model = fit_dynamics(train, arm3, SGPOptions())
    assert model.hyperparameters_["joint3"]["guard_choice"] == "two-stage"
    cov = _coverage(model, test)
    assert np.all(cov >= 0.85), cov
    est = model.gp_  # the alternative: PR's own residual everywhere (the check can fail)
    q, qd, qdd = (train.stream(s).select(arm3.joint_names).data for s in ("q", "qd", "qdd"))
    Us, Fs = est._scale(np.hstack([q, qd, qdd]), model.features(q, qd, qdd))
    own = train.stream("tau").select(arm3.joint_names).data - est.pr_posterior_.predict(Us, Fs, variance=False)[0]
    est.pr_posterior_.w_cov_robust = parametric_robust_w_cov(est.pr_posterior_, Fs, own)
    wide = _coverage(model, test)[2]
    assert wide > 0.99 and cov[2] < wide - 0.005, (cov, wide)


def test_beyond_its_gp_s_data_a_two_stage_band_takes_pr_s_w_variance():
    """Run 58 at 200 samples: the guard gives joint 3 two stages; W's variance from what both
    stages leave held 0.84 of the held-out torque (the test leaves the 4 s of training, where the
    GP on PR's residual reverts to its prior mean and the two stages err as PR); weighted towards
    PR's own by the GP's posterior over prior variance it holds it within 0.85-0.99."""
    run = held_out_run(58)
    model = fit_dynamics(run.train, run.arm3, SGPOptions())
    assert model.hyperparameters_["joint3"]["guard_choice"] == "two-stage"
    cov = _coverage(model, run.test)
    assert np.all((cov >= 0.85) & (cov <= 0.99)), cov
    est = model.gp_  # without the weighting (the check can fail)
    est._two_stage_w_variance = lambda U, F, Fs, v_pr, gp_var, j: v_pr[:, j]
    assert _coverage(model, run.test)[2] < 0.85
