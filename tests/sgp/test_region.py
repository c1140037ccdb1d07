"""The two-stage GP cut at an onset in its joint's angle (kernels.Region, guard._region_scan): a
friction confined to part of the range is found where it starts, and predicted better than by an
uncut GP; a residual without a step is left uncut."""

from dataclasses import replace

import numpy as np
import pytest

from diegocal.sgp import DEFAULT_GUARD, SemiParametricGP, SquaredExponential, Stages, Subspace, nested
from diegocal.sgp.gp import Hyperparameters, fit_posterior
from diegocal.sgp.guard_options import TWO_STAGE
from diegocal.sgp.kernels import REGION_OFF, Region, is_amplitude
from diegocal.sgp.region import _OutputLikelihood

ONSET = 0.5  # rad: output 0 has a friction above it
W_TRUE = np.array([1.0, 0.5])


def _run(seed, N=900, duration=30.0):
    """A joint swept by a sum of sines (angle, velocity, 100 Hz-like samples in time order): two
    outputs linear in (sin angle, a command), output 0 with a Coulomb + viscous friction above
    ONSET, noise 0.02."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, duration, N)
    f = rng.uniform(0.15, 0.35, 2)
    p = rng.uniform(0, 2 * np.pi, 2)
    angle = 0.6 * np.sin(2 * np.pi * f[0] * t + p[0]) + 0.35 * np.sin(2 * np.pi * f[1] * t + p[1])
    velocity = np.gradient(angle, t)
    U = np.column_stack([angle, velocity])
    F = np.zeros((N, 2, 2))
    F[:, :, 0] = np.sin(angle)[:, None]
    F[:, :, 1] = np.sin(2 * np.pi * 0.7 * t + rng.uniform(0, 6))[:, None]
    clean = F @ W_TRUE
    clean[:, 0] += (angle >= ONSET) * (0.3 * np.tanh(velocity / 0.05) + 0.2 * velocity)
    return U, clean + 0.02 * rng.standard_normal(clean.shape), F, clean


@pytest.fixture(scope="module")
def fits():
    U, Y, F, _ = _run(0)
    guard = replace(DEFAULT_GUARD, max_lengthscale=3.0)
    out = {}
    for label, regions in (("cut", (0, 0)), ("uncut", None)):
        kernels = [Subspace([0, 1], SquaredExponential(2)) for _ in range(2)]
        out[label] = SemiParametricGP(kernels, guard=guard, seed=0, region_inputs=regions).fit(U, Y, F)
    return out, (U, Y, F)


def test_the_onset_is_placed_between_the_right_two_samples_and_a_smooth_residual_is_not_cut(fits):
    out, (U, _, _) = fits
    est = out["cut"]
    theta = est.stages_.residual.theta
    onset = theta[0][0] * est.u_std_[0] + est.u_mean_[0]
    below, above = U[U[:, 0] < ONSET, 0].max(), U[U[:, 0] >= ONSET, 0].min()
    assert below < onset <= above  # no training angle between the friction's onset and the cut
    assert theta[1][0] == REGION_OFF  # output 1: PR explains it, no step


def test_the_guard_keeps_the_cut_and_predicts_a_new_run_better_than_without_it(fits):
    """Against the noiseless torque of another run: the guarded SGP that may cut (the guard keeps
    two stages, cut) against the same SGP without region inputs."""
    out, _ = fits
    Uq, _, Fq, clean = _run(1)
    err = {label: np.mean((est.predict(Uq, Fq)[0][:, 0] - clean[:, 0]) ** 2) for label, est in out.items()}
    assert out["cut"].selection_[0] == TWO_STAGE
    assert err["cut"] < err["uncut"] / 3, err


def _choose_cut(est, U, Y, F, monkeypatch, plain=None, nested=None):
    """Run the guard's first choice on the fitted cut estimator, its every-sample plain and
    nested scores of the cut replaced by ``plain`` and ``nested`` ((blocks, n) or None: the
    real ones); returns (confirmed outputs, the nested calls' outputs)."""
    monkeypatch.setattr(est, "_two_stage_hp", est._two_stage_hp)  # restored after the test
    monkeypatch.setattr(est, "_raw", (U, F), raising=False)
    labels = list(est.validation_blocks_)
    per_block = np.array([est.validation_blocks_[label].copy() for label in labels])
    blocks = np.array_split(np.arange(0, len(U), 3), 5)  # a subset's blocks, as above hyper_max
    pr_before = per_block[labels.index("parametric")][:, 0].copy()
    calls = []
    real_plain = type(est)._two_stage_plain

    def stub_plain(self, outputs, b, data, every_sample=False):
        return plain if every_sample and plain is not None else real_plain(self, outputs, b, data, every_sample)

    def stub_nested(self, outputs, b, data, **_):
        calls.append(list(outputs))
        return nested

    monkeypatch.setattr(type(est), "_two_stage_plain", stub_plain)
    if nested is not None:
        monkeypatch.setattr(type(est), "_two_stage_nested", stub_nested)
    Us, Fs = est._scale(U, F)
    confirmed = set()
    est._choose_cut(per_block, labels, confirmed, blocks, (Us, Y, Fs))
    assert np.all(np.isfinite(per_block[labels.index(TWO_STAGE)][:, 0]))
    pr = per_block[labels.index("parametric")][:, 0]
    if 0 in confirmed:  # the cut kept: PR on the cut's folds
        np.testing.assert_array_equal(pr, est._parametric_outside(blocks, (Us, Y, Fs))[:, 0])
    else:  # the cut lost: every candidate of the output back on the subset's folds
        np.testing.assert_array_equal(pr, pr_before)
    return confirmed, calls


def test_a_cut_that_loses_gives_its_output_back_to_the_uncut_two_stages(fits, monkeypatch):
    """Where the nested cross-validation rejects the cut, the output's two stages are the uncut
    GP again, scored by the plain cross-validation."""
    out, (U, Y, F) = fits
    est = out["cut"]
    zeros, worst = np.zeros((5, 2)), np.full((5, 2), np.inf)
    confirmed, calls = _choose_cut(est, U, Y, F, monkeypatch, plain=zeros, nested=worst)
    assert calls == [[0]]  # its plain scores won: confirmed nested, and the nested ones lose
    assert est._two_stage_hp[1].theta[0][0] == REGION_OFF
    assert 0 not in confirmed


def test_a_cut_whose_plain_scores_lose_is_not_confirmed_nested(fits, monkeypatch):
    """The every-sample plain scores screen the cut: where they lose to the guard's other choice,
    the (costly) nested refits are not run and the output goes back to the uncut GP."""
    out, (U, Y, F) = fits
    est = out["cut"]
    big = np.full((5, 2), 10.0)
    confirmed, calls = _choose_cut(est, U, Y, F, monkeypatch, plain=big, nested=np.zeros((5, 2)))
    assert calls == []
    assert est._two_stage_hp[1].theta[0][0] == REGION_OFF
    assert 0 not in confirmed


def test_a_cut_that_wins_is_confirmed_nested_against_pr_on_its_folds(fits, monkeypatch):
    """Plain and nested scores both winning, the cut is kept, confirmed, and PR's scores for its
    output are those of the same every-sample folds (checked in _choose_cut above)."""
    out, (U, Y, F) = fits
    est = out["cut"]
    confirmed, calls = _choose_cut(est, U, Y, F, monkeypatch, plain=np.zeros((5, 2)), nested=np.zeros((5, 2)))
    assert calls == [[0]] and 0 in confirmed
    assert est._two_stage_hp[1].theta[0][0] < REGION_OFF


def test_the_scan_of_hard_cuts_is_the_kernels_likelihood_with_a_hard_step(fits):
    """_OutputLikelihood.hard_cuts (each side diagonalised once) against the Region kernel's own
    likelihood with a step far sharper than the samples' spacing, every onset and amplitude pair."""
    out, (U, Y, F) = fits
    est = out["cut"]
    res_est = est._residual_estimator()
    kernel = res_est.kernels[0]
    Us = (U - est.u_mean_) / est.u_std_
    base = est._uncut_residual.theta[0]
    likelihood = _OutputLikelihood(kernel, Us, Y[:, 0] - Y[:, 0].mean(), -3.0, np.arange(0, len(U), 3))
    onsets = np.quantile(Us[:, 0], [0.1, 0.5, 0.83])
    amplitudes = (0.1, 1.0, 3.0)
    scores = likelihood.hard_cuts(base[3:], onsets, amplitudes)
    amp = 3 + [i for i, name in enumerate(kernel.kernel.names) if is_amplitude(name)][0]
    for i, c in enumerate(onsets):
        for b, below in enumerate(amplitudes):
            for a, above in enumerate(amplitudes):
                theta = base.copy()
                theta[:3] = c, np.log(1e-12), np.log(above / below)
                theta[amp] = base[amp] + np.log(below)
                assert abs(likelihood(theta) - scores[i, b, a]) < 1e-6


def test_a_cut_output_is_judged_against_pr_on_the_same_folds(fits, monkeypatch):
    """PR's scores for a cut output come from the same every-sample folds as the cut GP's."""
    out, (U, Y, F) = fits
    est = out["cut"]
    monkeypatch.setattr(est, "_raw", (U, F), raising=False)
    Us, Fs = est._scale(U, F)
    blocks = np.array_split(np.arange(0, len(U), 3), 5)  # a subset's blocks, as above hyper_max
    scores = est._parametric_outside(blocks, (Us, Y, Fs))
    hp_pr = est._two_stage_hp[0]
    for b, val in enumerate(blocks):
        fit = est._outside(None, val)
        post = fit_posterior([None, None], Us[fit], Y[fit], Fs[fit], hp_pr)
        mean = post.predict(Us[val], Fs[val], variance=False)[0]
        np.testing.assert_allclose(scores[b], np.mean((mean - Y[val]) ** 2, axis=0) / est.y_std_**2)


def test_a_model_saved_before_region_kernels_loads_uncut(fits):
    """Stages whose residual GP has the base kernel's parameters only (a file of an earlier
    version) restore with the onset off: the same prediction as the uncut GP's parameters."""
    out, (U, Y, F) = fits
    est = out["cut"]
    hp_pr, hp_res = est._two_stage_hp
    assert hp_res.theta[1][0] == REGION_OFF
    old = Hyperparameters(hp_res.log_sigma_w, hp_res.log_sigma_v, (hp_res.theta[0], hp_res.theta[1][3:]))
    means = []
    for residual in (hp_res, old):
        stages = Stages((TWO_STAGE, TWO_STAGE), hp_pr, residual)
        kernels = [Subspace([0, 1], SquaredExponential(2)) for _ in range(2)]
        restored = SemiParametricGP(kernels, guard=est.guard, seed=0, region_inputs=(0, 0))
        means.append(restored.fit(U, Y, F, est.hyper_, stages=stages).predict(U, F)[0])
    np.testing.assert_array_equal(means[0], means[1])


@pytest.mark.parametrize("learn_on", ["fit", "other samples"])
def test_a_nested_fold_cuts_at_the_same_angle_as_the_all_sample_fit(fits, monkeypatch, learn_on):
    """Each fold's estimator standardises its inputs by the fold's own mean and std (those it
    learns on and those it is fitted on may differ); the onset it holds must still be the same
    angle (rad)."""
    out, (U, Y, F) = fits
    est = out["cut"]
    hp_res = est._two_stage_hp[1]
    onset = hp_res.theta[0][0] * est.u_std_[0] + est.u_mean_[0]
    made = []
    build = type(est)._residual_estimator

    def spy(self, *args, **kwargs):
        made.append(build(self, *args, **kwargs))
        return made[-1]

    learnt = []
    learn = type(est)._learn_residual

    def keep(self, *args, **kwargs):
        learnt.append(learn(self, *args, **kwargs))
        return learnt[-1]

    monkeypatch.setattr(type(est), "_residual_estimator", spy)
    monkeypatch.setattr(type(est), "_learn_residual", keep)
    monkeypatch.setattr(est, "_raw", (U, F), raising=False)
    Us, Fs = est._scale(U, F)
    fit_idx, val_idx = np.arange(len(U) // 2), np.arange(len(U) // 2, len(U))  # a fold's scaling differs
    learn_idx = None if learn_on == "fit" else np.arange(len(U) // 8, len(U) // 3)
    est._two_stage_fold([0], fit_idx, val_idx, (Us, Y, Fs), learn_idx)
    fold = next(e for e in made if hasattr(e, "hyper_"))  # the one that fitted (others learnt)
    learner = next(e for e in made if hasattr(e, "u_mean_") and not hasattr(e, "hyper_"))
    on = fit_idx if learn_idx is None else learn_idx
    np.testing.assert_array_equal(learner.u_mean_, U[on].mean(0))  # it learnt on learn_idx
    np.testing.assert_array_equal(fold.u_mean_, U[fit_idx].mean(0))  # and was fitted on fit_idx
    assert not np.isclose(fold.u_mean_[0], est.u_mean_[0])
    np.testing.assert_allclose(fold.hyper_.theta[0][0] * fold.u_std_[0] + fold.u_mean_[0], onset, rtol=1e-12)
    # the learnt length-scales, in rad and rad/s, are the fitted ones (theta: c, w, r, σ_z, ℓ_q, ℓ_qd)
    raw = np.exp(learnt[-1].theta[0][4:]) * learner.u_std_[:2]
    np.testing.assert_allclose(np.exp(fold.hyper_.theta[0][4:]) * fold.u_std_[:2], raw, rtol=1e-12)


def test_rescaled_parameters_give_the_same_kernel_of_the_raw_inputs():
    """nested.rescaled: a cut SE kernel's parameters moved from one input standardisation to
    another give the same covariance of the raw inputs (length-scales, onset and width)."""
    rng = np.random.default_rng(3)
    U = rng.normal([1.0, -2.0], [0.5, 2.0], size=(60, 2))
    kernels = [Region(1, Subspace([0, 1], SquaredExponential(2))), None]
    theta = (np.array([0.3, np.log(0.2), np.log(2.0), np.log(0.7), np.log(0.4), np.log(1.3)]), np.zeros(0))
    source = (U.mean(0), U.std(0))
    target = (U[:20].mean(0), U[:20].std(0))
    moved = nested.rescaled(kernels, theta, source, target)
    K0 = kernels[0]((U - source[0]) / source[1], (U - source[0]) / source[1], theta[0])
    K1 = kernels[0]((U - target[0]) / target[1], (U - target[0]) / target[1], moved[0])
    np.testing.assert_allclose(K1, K0, rtol=1e-10, atol=1e-14)
    assert not np.allclose(moved[0], theta[0])
    assert moved[1].size == 0


@pytest.mark.parametrize("log_width", [np.log(1e-4), np.log(0.3)])
def test_the_cut_kernel_and_its_gradient_are_the_products_with_the_scale(log_width):
    """Region scales k_0 in place by rows (a row on either side of a sharp step is one vector):
    the same numbers, bit for bit, as the elementwise product with S = b bᵀ + r² a aᵀ, for a
    sharp step (most rows on one side) and a smooth one (every row on the step)."""
    rng = np.random.default_rng(4)
    X1, X2 = rng.normal(size=(70, 2)), rng.normal(size=(50, 2))
    kernel = Region(0, Subspace([0, 1], SquaredExponential(2)))
    theta = np.array([0.2, log_width, np.log(3.0), np.log(0.8), np.log(0.6), np.log(1.1)])
    a1, _, a2, _ = kernel._sides(X1, X2, theta)
    assert (np.mean((a1 == 0) | (a1 == 1)) > 0.9) == (log_width < -5)
    K0 = kernel.kernel(X1, X2, theta[3:])
    S = kernel._scale(a1, a2, theta)
    np.testing.assert_array_equal(kernel(X1, X2, theta), K0 * S)
    W = rng.normal(size=(70, 50))
    expected = kernel.kernel.weighted_gradient(X1, X2, theta[3:], W * S, K0)
    np.testing.assert_array_equal(kernel.weighted_gradient(X1, X2, theta, W)[3:], expected)


def test_a_cut_gp_is_scored_on_every_sample_outside_the_block(fits, monkeypatch):
    """With every_sample (the cut outputs' nested scores) each fold is fitted on every training
    sample outside the block's time span, not only on the other blocks' (subset) samples; its
    hyperparameters are learnt on those other blocks in both cases."""
    out, (U, Y, F) = fits
    est = out["cut"]
    seen = []

    def fold(self, outputs, fit_idx, val_idx, data, learn_idx=None):
        seen.append((fit_idx, val_idx, fit_idx if learn_idx is None else learn_idx))
        return np.zeros((len(val_idx), 2))

    monkeypatch.setattr(type(est), "_two_stage_fold", fold)
    monkeypatch.setattr(est, "_raw", (U, F), raising=False)
    blocks = np.array_split(np.arange(0, len(U), 3), 5)  # a subset's blocks, as above hyper_max
    Us, Fs = est._scale(U, F)
    for every in (False, True):
        seen.clear()
        est._two_stage_nested([0], blocks, (Us, Y, Fs), every_sample=every)
        for fit_idx, val_idx, learn_idx in seen:
            outside = np.flatnonzero((np.arange(len(U)) < val_idx.min()) | (np.arange(len(U)) > val_idx.max()))
            others = np.setdiff1d(np.concatenate(blocks), val_idx)
            np.testing.assert_array_equal(np.sort(fit_idx), outside if every else others)
            np.testing.assert_array_equal(np.sort(learn_idx), others)


def test_a_cut_gps_folds_are_capped_at_outside_max_samples_evenly_in_time(fits, monkeypatch):
    """Above OUTSIDE_MAX samples outside the block (a long log; the folds are fitted exactly),
    the fold keeps that many, evenly spaced in time, none inside the block's span."""
    out, (U, _, F) = fits
    est = out["cut"]
    monkeypatch.setattr(est, "_raw", (U, F), raising=False)
    monkeypatch.setattr(nested, "OUTSIDE_MAX", 100)
    val = np.arange(300, 480)
    fit = est._outside(None, val)
    assert len(fit) == 100 and fit[0] == 0 and fit[-1] == len(U) - 1
    assert not np.any((fit >= 300) & (fit < 480))
    assert np.ptp(np.diff(fit[fit < 300])) <= 1  # evenly: steps differ by rounding only


def _joint_cut_fit(U, Y, F):
    guard = replace(DEFAULT_GUARD, max_lengthscale=3.0)  # joint_region: on by default
    kernels = [Region(0, Subspace([0, 1], SquaredExponential(2))) for _ in range(2)]
    return SemiParametricGP(kernels, guard=guard, seed=0, region_inputs=(0, 0)).fit(U, Y, F)


def test_the_joint_cut_is_not_learnt_where_the_cut_two_stages_win(monkeypatch):
    """Guard.joint_region: the "cut" candidate is learnt only for the outputs whose cut two
    stages lose; here they win output 0 (their nested score 0.0011 against the joint GP's 0.0054)
    and the candidate is neither learnt nor scored."""
    U, Y, F, _ = _run(0)
    calls = []
    learn = SemiParametricGP._joint_cut
    monkeypatch.setattr(SemiParametricGP, "_joint_cut", lambda self, *a: calls.append(a) or learn(self, *a))
    est = _joint_cut_fit(U, Y, F)
    assert est.selection_ == ("two-stage", "parametric")
    assert calls == [] and "cut" not in est.validation_scores_


def test_joint_hyperparameters_saved_without_region_parameters_load_into_region_kernels():
    """A model saved with plain joint kernels (the default guard before the joint cut was on by
    default) reloads into Region kernels with the onset off and predicts as it did."""
    U, Y, F, _ = _run(0)
    plain = [Subspace([0, 1], SquaredExponential(2)) for _ in range(2)]
    saved = SemiParametricGP(plain, seed=0).fit(U, Y, F)
    region = [Region(0, k) for k in plain]
    back = SemiParametricGP(region, seed=0).fit(U, Y, F, saved.hyper_)
    assert all(t[0] == REGION_OFF for t in back.hyper_.theta)
    Uq, _, Fq, _ = _run(1)
    np.testing.assert_allclose(back.predict(Uq, Fq)[0], saved.predict(Uq, Fq)[0], rtol=1e-10, atol=1e-12)


@pytest.mark.slow
def test_the_joint_cut_candidate_cuts_where_the_two_stages_lost_and_competes_only_there(fits, monkeypatch):
    """Guard.joint_region: where the cut two stages lose (here made to: every nested score of two
    stages ×10, still 8 times better than PR's: PR's residual has structure), the "cut"
    candidate is the joint GP cut at the two stages' onset (the same standardised value: both
    estimators scale the same inputs), scored only for the outputs it cuts. It then wins output
    0: cut between the right two training angles, it predicts a new run as the cut two stages
    do, 3 times better than the uncut GP."""
    U, Y, F, _ = _run(0)

    real_nested = SemiParametricGP._two_stage_nested

    def lose(self, outputs, blocks, data, every_sample=False):
        return 10.0 * real_nested(self, outputs, blocks, data, every_sample)

    monkeypatch.setattr(SemiParametricGP, "_two_stage_nested", lose)
    est = _joint_cut_fit(U, Y, F)
    scores = est.validation_scores_["cut"]
    assert np.isfinite(scores[0]) and np.isinf(scores[1])  # output 1 has no step: not cut
    assert est.selection_ == ("cut", "parametric")
    theta = est.hyper_.theta
    onset = theta[0][0] * est.u_std_[0] + est.u_mean_[0]
    below, above = U[U[:, 0] < ONSET, 0].max(), U[U[:, 0] >= ONSET, 0].min()
    assert below < onset <= above
    assert theta[1][0] == REGION_OFF
    Uq, _, Fq, clean = _run(1)
    out, _ = fits
    err = {label: np.mean((m.predict(Uq, Fq)[0][:, 0] - clean[:, 0]) ** 2) for label, m in out.items()}
    err["joint cut"] = np.mean((est.predict(Uq, Fq)[0][:, 0] - clean[:, 0]) ** 2)
    assert err["joint cut"] < err["uncut"] / 3 and err["joint cut"] < 1.2 * err["cut"], err


def test_the_two_stage_gp_s_amplitude_above_the_onset_is_capped_by_the_residual_there():
    """guard_options.capped_above: r·σ_z of a cut kernel at most MAX_AMPLITUDE_ABOVE times the residual's
    std over the samples above the onset; a kernel not cut, or one within the cap, unchanged."""
    from types import SimpleNamespace

    from diegocal.sgp.guard_options import MAX_AMPLITUDE_ABOVE, capped_above

    rng = np.random.default_rng(0)
    U = np.column_stack([rng.uniform(-1, 1, 400), rng.normal(size=400)])
    res = np.where(U[:, 0] >= 0.5, 0.3, 0.01) * rng.standard_normal(400)
    est = SimpleNamespace(u_mean_=np.zeros(2), u_std_=np.ones(2))  # U taken as standardised
    kernel = Region(0, Subspace([0, 1], SquaredExponential(2)))
    names = kernel.names
    amp = [i for i, n in enumerate(names) if is_amplitude(n)][0]
    ratio = names.index("log_region_ratio")
    theta = np.zeros(len(names))
    theta[0], theta[1], theta[amp] = 0.5, np.log(1e-3), np.log(0.05)
    theta[ratio] = np.log(100.0)  # 5 N·m above: 17× the residual there
    out = capped_above(kernel, theta, est, U, res)
    std_above = res[U[:, 0] >= 0.5].std()
    np.testing.assert_allclose(np.exp(out[ratio] + out[amp]), MAX_AMPLITUDE_ABOVE * std_above, rtol=1e-12)
    np.testing.assert_array_equal(np.delete(out, ratio), np.delete(theta, ratio))
    theta[ratio] = np.log(2.0)  # 0.1 N·m: within the cap
    np.testing.assert_array_equal(capped_above(kernel, theta, est, U, res), theta)
    theta[0] = REGION_OFF  # not cut
    theta[ratio] = np.log(100.0)
    np.testing.assert_array_equal(capped_above(kernel, theta, est, U, res), theta)
