"""What "calibrated" can mean for one held-out run. PR's ±2σ band on the scale bench's arm3 run 29
*without* the hidden friction (``friction_case(..., hidden=False)``), where the rigid body with
viscous and Coulomb friction is the true model and the noise white: PR's posterior is then the
exact one. Redrawing the training noise (same trajectory, same robot) and testing on 2,000
samples of another trajectory, the band covers 0.95 on average over redraws on every joint, yet a
200-sample run's coverage of joint 2 strays outside 0.85-0.99: W's error, one draw per training
run, is shared by every test sample and dominates the band where the test leaves the 4 s of
training. This is why ``bench/bench_sgp_sizes.py`` judges coverage as a mean over runs and counts
the runs out of range beside this reference."""

from dataclasses import replace

import numpy as np

from diegocal.io import make_stream
from diegocal.robot import BUNDLED_ROBOTS, load_robot
from diegocal.sgp import SGPOptions, fit_dynamics
from experiments.sgp.common import CASE_NOISE, friction_case, same_robot

REDRAWS = 100


def test_pr_s_band_is_calibrated_over_noise_redraws_where_pr_is_the_true_model():
    arm3 = load_robot(BUNDLED_ROBOTS / "arm3")
    train = friction_case(arm3, 200, 29, hidden=False).slice(0, 200)
    test = friction_case(arm3, 2000, 1029, same_robot(train, arm3), hidden=False).slice(0, 2000)
    tau = test.stream("tau").select(arm3.joint_names).data
    clean, names = train.truth.signals["tau"].data, train.stream("tau").names
    rng = np.random.default_rng(0)
    cover, noise_only = [], []
    for _ in range(REDRAWS):
        noisy = make_stream(names, clean + CASE_NOISE * rng.standard_normal(clean.shape))
        model = fit_dynamics(replace(train, streams={**train.streams, "tau": noisy}), arm3, SGPOptions(kind="pr"))
        pred = model.predict(test)
        err = np.abs(pred.tau - tau)
        cover.append(np.mean(err <= 2 * pred.tau_std, axis=0))
        noise_only.append(np.mean(err <= 2 * np.sqrt(model.gp_.noise_var_), axis=0))  # W's error left out
    cover, noise_only = np.array(cover), np.array(noise_only)
    assert np.all(np.abs(cover.mean(axis=0) - 0.95) <= 0.02), cover.mean(axis=0)
    assert np.mean(noise_only.mean(axis=0)) < 0.93, noise_only.mean(axis=0)  # the check can fail
    assert cover[:, 1].min() < 0.85, np.sort(cover[:, 1])[:10]  # single runs stray (3 of 100: 0.76-0.80)
