"""The guard's two stages (Guard.two_stage): an output the guard gives to PR is predicted by PR
itself, one it gives two stages by PRGP itself (thesis §3.4.1: PR, then a GP on its residual),
whatever the other outputs' GPs do to the shared W; and two stages replace the guard's choice
among the other candidates only where they beat it by more than one standard error."""

from dataclasses import replace

import numpy as np
import pytest

from diegocal.sgp import DEFAULT_GUARD, SemiParametricGP, SquaredExponential, Stages
from diegocal.sgp.gp import fit_posterior, parametric_robust_w_cov
from diegocal.sgp.guard_options import JOINT, MIN_GP_GAIN, MIN_TWO_STAGE_GAIN, PARAMETRIC, TWO_STAGE

from .test_guard import W_TRUE, _data


@pytest.fixture(scope="module")
def data():
    return _data(np.random.default_rng(5), 160, (-1.0, 1.0), (0.0, 1.0))


def _kernels():
    return [SquaredExponential(3) for _ in range(2)]


def test_two_stages_predict_as_pr_and_prgp(data):
    """Restore a fit whose guard chose two stages for output 0 and PR for output 1: output 0 is
    PR's mean plus the residual GP's, output 1 is PR's, to rounding. Output 1's band is PR's;
    output 0's is the residual GP's variance plus W's, from what both stages leave of the
    training outputs on the GP's data, from PR's own residual beyond it, weighted by the GP's
    posterior over prior variance."""
    U, Y, F, _ = data
    pr = SemiParametricGP([None, None], seed=0).fit(U, Y, F)
    res_gp = SemiParametricGP(_kernels(), use_features=False, seed=0).fit(U, Y - pr.predict(U, F)[0], F)
    guarded = SemiParametricGP(_kernels(), guard=DEFAULT_GUARD, seed=0).fit(U, Y, F)  # any joint fit
    stages = Stages((TWO_STAGE, PARAMETRIC), pr.hyper_, res_gp.hyper_)
    est = SemiParametricGP(_kernels(), guard=DEFAULT_GUARD, seed=0).fit(U, Y, F, guarded.hyper_, stages=stages)
    Uq, _, Fq, _ = _data(np.random.default_rng(6), 50, (-1.5, 1.5), (0.0, 2.0))
    mean, var, par = est.predict(Uq, Fq)
    _, v_own, _ = pr.predict(Uq, Fq)  # PR's band, W's robust variance from its own residual
    left = Y - pr.predict(U, F, variance=False)[0]  # W's robust variance: what both stages leave
    left[:, 0] -= res_gp.predict(U, F, variance=False)[0][:, 0]
    pr.posterior_.w_cov_robust = parametric_robust_w_cov(pr.posterior_, pr._scale(U, F)[1], left)
    m_pr, v_pr, p_pr = pr.predict(Uq, Fq)
    m_gp, v_gp, _ = res_gp.predict(Uq, Fq)
    blk = res_gp.posterior_.blocks[0]
    far = v_gp[:, 0] / blk.kernel.diag(res_gp._scale(Uq, Fq[:, :, :0])[0], blk.theta)
    np.testing.assert_allclose(mean[:, 0], m_pr[:, 0] + m_gp[:, 0], rtol=1e-9, atol=1e-12)
    w_var = (1 - far) * v_pr[:, 0] + far * v_own[:, 0]
    np.testing.assert_allclose(var[:, 0], v_gp[:, 0] + w_var, rtol=1e-9, atol=1e-15)
    assert far.min() < 0.01 and far.max() > 0.3  # from one account of W's error towards the other
    np.testing.assert_allclose(mean[:, 1], m_pr[:, 1], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(var[:, 1], v_own[:, 1], rtol=1e-9, atol=1e-15)
    assert not np.allclose(v_own[:, 1], v_pr[:, 1], rtol=1e-4)  # the two robust variances differ
    np.testing.assert_allclose(par, p_pr, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(est.noise_var_, [res_gp.noise_var_[0], pr.noise_var_[1]])
    np.testing.assert_allclose(est.w_, pr.w_)  # no output is joint: the W that predicts is PR's


def test_the_guard_offers_two_stages_and_keeps_pr_where_no_gp_earns_its_place(data):
    U, Y, F, clean = data
    est = SemiParametricGP(_kernels(), guard=DEFAULT_GUARD, seed=0).fit(U, Y, F)
    assert TWO_STAGE in est.validation_scores_
    assert est.selection_[0] != PARAMETRIC  # the friction on output 0 is worth a GP
    without = SemiParametricGP(_kernels(), guard=replace(DEFAULT_GUARD, two_stage=False), seed=0).fit(U, Y, F)
    assert TWO_STAGE not in without.validation_scores_


def test_two_stages_must_beat_the_guards_other_choice_by_one_standard_error():
    """_choose on options (learnt, two-stage, parametric) × 5 blocks × 6 outputs."""
    pr = np.array([1.0, 1.2, 0.9, 1.1, 1.0])
    wiggle = 0.01 * np.array([1, -1, 1, -1, 1])
    per_block = np.stack(
        [
            np.column_stack([pr - 0.30, pr - 0.30, pr + 0.1, pr - 0.30, pr - 0.01 + 3 * wiggle, pr]),  # learnt
            np.column_stack(
                [pr - 0.10, pr - 0.31 + 3 * wiggle, pr + 0.1, pr - 0.40, pr - 0.20, 0.9995 * pr]
            ),  # two-stage
            np.column_stack([pr, pr, pr, pr, pr, pr]),  # parametric
        ]
    )
    # 0: learnt beats two stages; 1: two stages lower, by less than one SE -> learnt (the guard's
    # choice without them); 2: no GP beats PR; 3: two stages beat learnt by more than one SE;
    # 4: learnt does not beat PR by one SE, two stages do; 5: two stages beat PR consistently but
    # by 0.05 % of its nMSE (under MIN_TWO_STAGE_GAIN): PR
    assert SemiParametricGP._choose(per_block, ["learnt", TWO_STAGE, PARAMETRIC]).tolist() == [0, 0, 2, 1, 1, 2]


def test_a_gp_must_beat_pr_by_the_minimum_gain():
    """Gains consistent over every block (far beyond one SE): under MIN_GP_GAIN of PR's nMSE a
    GP, joint or two stages, gives way to PR; two stages need only MIN_TWO_STAGE_GAIN over a
    joint GP. Outputs: 0 learnt 1 % better than PR; 1 learnt 3 % better; 2 two stages 1 % better
    than PR, learnt no better; 3 learnt 10 % better, two stages 1 % better than learnt."""
    pr = np.array([1.0, 1.2, 0.9, 1.1, 1.0])
    learnt = np.column_stack([0.99 * pr, 0.97 * pr, pr, 0.90 * pr])
    two_stage = np.column_stack([1.1 * pr, 1.1 * pr, 0.99 * pr, 0.891 * pr])
    per_block = np.stack([learnt, two_stage, np.column_stack([pr] * 4)])
    assert MIN_TWO_STAGE_GAIN < 0.01 < MIN_GP_GAIN < 0.03
    assert SemiParametricGP._choose(per_block, ["learnt", TWO_STAGE, PARAMETRIC]).tolist() == [2, 0, 2, 1]


def test_two_stages_are_confirmed_with_each_folds_gp_learnt_without_its_block(data):
    """The confirmation of two stages (GuardCandidates._two_stage_nested): a fold's GP is learnt
    on the other blocks only, so a disturbance in the validation block's measurements moves the
    fold's prediction of that block far less than it moves the plain cross-validation's, whose
    hyperparameters were learnt on every sample (the disturbance reaches the fold only through
    its start, the all-sample optimum)."""
    U, Y, F, _ = data
    blocks = np.array_split(np.arange(len(U)), 5)
    fit_idx, val_idx = np.concatenate(blocks[:2] + blocks[3:]), blocks[2]
    disturbed = Y.copy()
    disturbed[val_idx, 0] += 0.2 * np.sin(40.0 * U[val_idx, 1])  # a wiggle the GP can chase
    nested, plain = [], []
    for y in (Y, disturbed):
        est = SemiParametricGP(_kernels(), guard=DEFAULT_GUARD, seed=0)
        est.learn(U, y, F)
        Us, Fs = est._scale(U, F)
        nested.append(est._two_stage_fold([0], fit_idx, val_idx, (Us, y, Fs))[:, 0])
        fold = (Us[fit_idx], y[fit_idx], Fs[fit_idx], Us[val_idx], Fs[val_idx])
        plain.append(est._two_stage_mean(*est._two_stage_hp, *fold)[:, 0])
    moved_plain = np.abs(plain[1] - plain[0]).max()
    assert moved_plain > 1e-3  # the disturbance reaches the plain cross-validation
    assert np.abs(nested[1] - nested[0]).max() < 0.1 * moved_plain
    _assert_predicts_as_well(nested[0], plain[0], Y[val_idx, 0], F[val_idx, 0])


def test_joint_gps_are_confirmed_with_each_folds_hyperparameters_learnt_without_its_block(data):
    """The same for the joint candidates on a small cross-validation (GuardCandidates._joint_nested):
    the fold's hyperparameters are learnt on the other blocks from the all-sample optimum."""
    U, Y, F, _ = data
    blocks = np.array_split(np.arange(len(U)), 5)
    fit_idx, val_idx = np.concatenate(blocks[:2] + blocks[3:]), blocks[2]
    disturbed = Y.copy()
    disturbed[val_idx, 0] += 0.2 * np.sin(40.0 * U[val_idx, 1])
    nested, plain = [], []
    for y in (Y, disturbed):
        est = SemiParametricGP(_kernels(), guard=replace(DEFAULT_GUARD, validation_fraction=0.0), seed=0)
        learnt = est.learn(U, y, F)  # ML-II on every sample, no guard
        Us, Fs = est._scale(U, F)
        hp0, resid = est._initial(Us, y, Fs)
        data = (Us, y, Fs)
        sizes = [k.n_params for k in est.kernels]
        fold = est._joint_fold(learnt.pack(), fit_idx, val_idx, data, sizes, est._bounds(hp0, resid), resid)
        nested.append(fold[:, 0])
        post = fit_posterior(est.kernels, Us[fit_idx], y[fit_idx], Fs[fit_idx], learnt)
        plain.append(post.predict(Us[val_idx], Fs[val_idx], variance=False)[0][:, 0])
    moved_plain = np.abs(plain[1] - plain[0]).max()
    assert moved_plain > 1e-3
    assert np.abs(nested[1] - nested[0]).max() < 0.1 * moved_plain
    _assert_predicts_as_well(nested[0], plain[0], Y[val_idx, 0], F[val_idx, 0])


def _assert_predicts_as_well(nested, plain, y, features):
    """The fold's own model predicts its block about as well as the plain cross-validation's
    and far better than the parametric part alone would with the friction left out (a fold
    that dropped its GP, or scaled its inputs wrongly, would not)."""
    mse = lambda m: float(np.mean((m - y) ** 2))  # noqa: E731
    assert mse(nested) < 1.5 * mse(plain)
    assert mse(nested) < 0.1 * mse(features @ W_TRUE)


def test_nested_scores_decide_the_guards_choice(data, monkeypatch):
    """The wiring of the confirmations in _validate: plain cross-validation scores that the
    nested ones overturn. Output 0 (the friction) wins with a joint GP in the plain scores; when
    every joint candidate's nested score is worse than PR's, it takes two stages, and when the
    nested two-stage scores are worse too, PR (and validation_scores_ holds the nested ones)."""
    U, Y, F, _ = data
    guard = replace(DEFAULT_GUARD, extend_capped=False)
    assert SemiParametricGP(_kernels(), guard=guard, seed=0).fit(U, Y, F).selection_[0] in JOINT

    def worse(*args, **kwargs):
        return np.full((5, 2), 10.0) + np.arange(5)[:, None]  # 5 blocks, nMSE far above PR's

    monkeypatch.setattr(SemiParametricGP, "_joint_nested", worse)
    est = SemiParametricGP(_kernels(), guard=guard, seed=0).fit(U, Y, F)
    assert est.selection_[0] == TWO_STAGE
    monkeypatch.setattr(SemiParametricGP, "_two_stage_nested", worse)
    est = SemiParametricGP(_kernels(), guard=guard, seed=0).fit(U, Y, F)
    assert est.selection_[0] == PARAMETRIC
    assert est.validation_scores_[TWO_STAGE][0] == est.validation_scores_["learnt"][0] == 12.0
