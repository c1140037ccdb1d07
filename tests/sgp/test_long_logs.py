"""The PR fit's lean routes for long logs (issue #33) equal the direct ones: W's system formed from
F_j itself where a block has no kernel, the robust covariance's block sums without a copy of F,
features scaled in place, and the in-sample score predicted in chunks."""

import numpy as np
import pytest

from diegocal.sgp import estimator as estimator_module
from diegocal.sgp import model as model_module
from diegocal.sgp.estimator import SemiParametricGP
from diegocal.sgp.gp import ROBUST_BLOCKS, Hyperparameters, _blocks, _shared_w, fit_posterior, robust_w_cov
from diegocal.sgp.kernels import SquaredExponential
from diegocal.sgp.model import DynamicsModel
from diegocal.sgp.options import SGPOptions
from diegocal.sgp.pr_sums import GramSums, posterior_from_sums
from diegocal.sgp.regressor import base_regressor
from diegocal.sgp.streams import log_arrays, torque_array
from diegocal.sgp.terms import term_columns
from diegocal.terms import make_term


def _data(seed=0, N=57, n=3, m=4, p=2):
    rng = np.random.default_rng(seed)
    U = rng.standard_normal((N, p))
    F = rng.standard_normal((N, n, m))
    Y = F @ rng.standard_normal(m) + np.cos(U[:, :1]) + 0.1 * rng.standard_normal((N, n))
    return U, Y, F


@pytest.mark.parametrize("with_gp", [False, True])
def test_lean_shared_w_equals_the_solves_of_every_block(with_gp):
    U, Y, F = _data()
    kernels = [SquaredExponential(2) if with_gp else None, None, None]
    theta = (np.array([0.1, -0.2, 0.3]) if with_gp else np.zeros(0), np.zeros(0), np.zeros(0))
    hp = Hyperparameters(np.log(2.0), np.log([0.1, 0.2, 0.3]), theta)
    blocks = _blocks(kernels, U, hp, np.exp(2.0 * hp.log_sigma_v), None)
    kept = _shared_w(blocks, Y, F, 4.0, keep=True)
    lean = _shared_w(blocks, Y, F, 4.0, keep=False)
    assert [g is None for g in lean[1]] == [k is None for k in kernels]
    for a, b in zip(kept[2:], lean[2:], strict=True):  # B, b, L_M, ŵ, α
        np.testing.assert_allclose(b, a, rtol=1e-12, atol=1e-14)


def test_robust_w_cov_block_sums_equal_the_per_sample_scores():
    U, Y, F = _data(seed=1, N=103)
    hp = Hyperparameters(np.log(2.0), np.log([0.1, 0.2, 0.3]), (np.zeros(0),) * 3)
    post = fit_posterior([None] * 3, U, Y, F, hp)
    parametric = np.array([True, False, True])
    alpha = (Y - F @ post.w_mean) / post.noise_var
    h = np.einsum("tjm,tj->tm", F[:, parametric], alpha[:, parametric])  # the direct route
    s = np.array([part.sum(axis=0) for part in np.array_split(h, ROBUST_BLOCKS)])
    m_inv = np.linalg.inv(post.M_chol @ post.M_chol.T)
    direct = m_inv @ (s.T @ s * ROBUST_BLOCKS / (ROBUST_BLOCKS - 1)) @ m_inv
    np.testing.assert_allclose(robust_w_cov(F, alpha, post.M_chol, parametric), direct, rtol=1e-10)


def test_a_block_without_kernel_keeps_no_training_features():
    U, Y, F = _data()
    hp = Hyperparameters(np.log(2.0), np.log([0.1, 0.2, 0.3]), (np.zeros(0),) * 3)
    post = fit_posterior([None] * 3, U, Y, F, hp)
    assert all(blk.F.shape == (0, F.shape[2]) for blk in post.blocks)
    mean, var, _ = post.predict(U[:5], F[:5])
    np.testing.assert_allclose(mean, F[:5] @ post.w_mean, rtol=1e-12)


def test_pr_features_scaled_in_place_give_the_same_fit():
    U, Y, F = _data(seed=2, N=200)
    plain = SemiParametricGP([None] * 3).fit(U, Y, F.copy())
    G = F.copy()
    lean = SemiParametricGP([None] * 3).fit(U, Y, G, overwrite_features=True)
    np.testing.assert_array_equal(G, F / lean.f_scale_)  # G's memory reused for the scaled F
    np.testing.assert_allclose(lean.w_, plain.w_, rtol=1e-12)
    np.testing.assert_allclose(lean.w_cov_, plain.w_cov_, rtol=1e-12)
    np.testing.assert_allclose(lean.log_likelihood_, plain.log_likelihood_, rtol=1e-12)


def test_in_sample_score_in_chunks_equals_one_prediction(arm2, simulate, monkeypatch):
    log, _ = simulate(arm2, T=120, seed=3)
    q, qd, qdd = log_arrays(log, arm2, need_tau=False)
    tau, joints = torque_array(log, arm2)
    monkeypatch.setattr(model_module, "PREDICT_SAMPLES", 7)
    model = DynamicsModel(arm2, SGPOptions(kind="pr"), tau_joints=joints).fit_arrays(q, qd, qdd, tau)
    whole = model.predict_arrays(q, qd, qdd, variance=False).tau
    np.testing.assert_allclose(model.mean_in_chunks(q, qd, qdd, None), whole, rtol=1e-13, atol=1e-13)
    np.testing.assert_allclose(model.nmse_in_sample_, model_module.nmse(whole, tau), rtol=1e-12)


def test_features_with_terms_written_in_chunks_equal_the_concatenated_columns(arm2, simulate, monkeypatch):
    log, _ = simulate(arm2, T=50, seed=4)
    q, qd, qdd = log_arrays(log, arm2, need_tau=False)
    tau, joints = torque_array(log, arm2)
    term = make_term("stribeck_friction", "elbow", {"velocity_scale": 0.05})
    model = DynamicsModel(arm2, SGPOptions(kind="pr"), tau_joints=joints, terms=(term,)).fit_arrays(q, qd, qdd, tau)
    monkeypatch.setattr(model_module, "PREDICT_SAMPLES", 7)
    base = base_regressor(arm2, q, qd, qdd, model.base_, model.options.friction)
    whole = np.concatenate([base, term_columns(model.terms, arm2, q, qd, qdd)], axis=2)
    np.testing.assert_array_equal(model.features(q, qd, qdd), whole)


@pytest.mark.parametrize("chunk", [1, 13, 200])
def test_pr_posterior_from_block_sums_equals_the_whole_features(chunk):
    U, Y, F = _data(seed=5, N=97)
    hp = Hyperparameters(np.log(2.0), np.log([0.1, 0.2, 0.3]), (np.zeros(0),) * 3)
    whole = fit_posterior([None] * 3, U, Y, F, hp)
    sums = GramSums(*F.shape)
    for i in range(0, len(Y), chunk):  # chunks that cross the robust blocks' edges
        sums.add(F[i : i + chunk], Y[i : i + chunk])
    assert sums.rows == len(Y)
    lean = posterior_from_sums(sums, U, hp)
    np.testing.assert_allclose(lean.w_mean, whole.w_mean, rtol=1e-11)
    np.testing.assert_allclose(lean.M_chol, whole.M_chol, rtol=1e-11)
    np.testing.assert_allclose(lean.w_cov_robust, whole.w_cov_robust, rtol=1e-9)
    np.testing.assert_allclose(lean.log_likelihood, whole.log_likelihood, rtol=1e-12)
    np.testing.assert_allclose(lean.predict(U[:5], F[:5])[1], whole.predict(U[:5], F[:5])[1], rtol=1e-10)


def test_pr_fit_in_chunks_equals_the_fit_on_whole_features(monkeypatch):
    U, Y, F = _data(seed=6, N=1500, m=5)
    monkeypatch.setattr(estimator_module, "CHUNK_SAMPLES", 333)
    plain = SemiParametricGP([None] * 3, hyper_max=400).fit(U, Y, F.copy())
    asked = []

    def features(rows):
        asked.append(np.arange(len(Y))[rows].size)
        return F[rows]

    lean = SemiParametricGP([None] * 3, hyper_max=400).fit_in_chunks(U, Y, features)
    assert max(asked) <= 400  # never the whole features: chunks, then the hyperparameter subset
    # the same subset and starts; ML-II may stop a hair apart (the scale's sums differ in order)
    np.testing.assert_allclose(lean.hyper_.pack(), plain.hyper_.pack(), rtol=1e-5)
    np.testing.assert_allclose(lean.w_, plain.w_, rtol=1e-6)
    np.testing.assert_allclose(lean.w_cov_, plain.w_cov_, rtol=1e-5)
    assert lean.inducing_ is None and plain.inducing_ is None  # sgp.yaml's n_inducing: null for PR
    given = SemiParametricGP([None] * 3).fit_in_chunks(U, Y, features, plain.hyper_)
    np.testing.assert_allclose(given.w_, plain.w_, rtol=1e-11)
    np.testing.assert_allclose(given.log_likelihood_, plain.log_likelihood_, rtol=1e-12)
    with pytest.raises(ValueError, match="PR only"):
        SemiParametricGP([SquaredExponential(2), None, None]).fit_in_chunks(U, Y, features)
