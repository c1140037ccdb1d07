"""The Woodbury route equals the dense route (thesis eq. 3.8-3.20), and sparse equals exact
when the inducing inputs are the data."""

import numpy as np
from scipy.signal import lfilter
from scipy.stats import multivariate_normal

from diegocal.sgp.gp import Hyperparameters, fit_posterior
from diegocal.sgp.kernels import SquaredExponential, Subspace


def _tiny(seed=0, N=15, n=2, m=3, p=2):
    rng = np.random.default_rng(seed)
    U = rng.standard_normal((N, p))
    F = rng.standard_normal((N, n, m))
    Y = F @ rng.standard_normal(m) + np.cos(U[:, :1]) + 0.1 * rng.standard_normal((N, n))
    kernels = [SquaredExponential(p), Subspace([1], SquaredExponential(1))]
    hp = Hyperparameters(np.log(2.0), np.log([0.1, 0.2]), (np.array([0.1, -0.2, 0.3]), np.array([-0.1, 0.2])))
    Uq, Fq = rng.standard_normal((7, p)), rng.standard_normal((7, n, m))
    return U, Y, F, kernels, hp, Uq, Fq


def _dense(U, Y, F, kernels, hp, Uq, Fq):
    """Brute force: σ_dd (3.13-3.15), σ_qd (3.16-3.19), mean (3.8), var (3.20); y output-major."""
    N, n = Y.shape
    sw2, sv2 = np.exp(2 * hp.log_sigma_w), np.exp(2 * hp.log_sigma_v)
    Fs = np.concatenate([F[:, j] for j in range(n)])  # (nN, m)
    Kdd = sw2 * Fs @ Fs.T
    for j in range(n):
        blk = slice(j * N, (j + 1) * N)
        Kdd[blk, blk] += kernels[j](U, U, hp.theta[j]) + sv2[j] * np.eye(N)
    y = np.concatenate([Y[:, j] for j in range(n)])
    mean, var = np.zeros((len(Uq), n)), np.zeros((len(Uq), n))
    for j in range(n):
        for a in range(len(Uq)):
            sqd = sw2 * Fq[a, j] @ Fs.T
            sqd[j * N : (j + 1) * N] += kernels[j](Uq[a : a + 1], U, hp.theta[j])[0]
            sqq = sw2 * Fq[a, j] @ Fq[a, j] + kernels[j](Uq[a : a + 1], Uq[a : a + 1], hp.theta[j])[0, 0]
            k = np.linalg.solve(Kdd, sqd)
            mean[a, j] = k @ y
            var[a, j] = sqq - k @ sqd
    ll = multivariate_normal(np.zeros(n * N), Kdd).logpdf(y)
    return mean, var, ll


def test_woodbury_posterior_equals_dense_computation():
    U, Y, F, kernels, hp, Uq, Fq = _tiny()
    post = fit_posterior(kernels, U, Y, F, hp)
    mean, var, _ = post.predict(Uq, Fq)
    dmean, dvar, dll = _dense(U, Y, F, kernels, hp, Uq, Fq)
    np.testing.assert_allclose(mean, dmean, rtol=1e-8, atol=1e-10)
    np.testing.assert_allclose(var, dvar, rtol=1e-7, atol=1e-10)
    np.testing.assert_allclose(post.log_likelihood, dll, rtol=1e-10)


def test_pr_and_gp_special_cases_equal_dense():
    U, Y, F, kernels, hp, Uq, Fq = _tiny(seed=1)
    # GP: no features (eq. 3.21)
    gp = fit_posterior(kernels, U, Y, F[:, :, :0], hp).predict(Uq, Fq[:, :, :0])
    d = _dense(U, Y, F[:, :, :0], kernels, hp, Uq, Fq[:, :, :0])
    np.testing.assert_allclose(gp[0], d[0], atol=1e-9)
    np.testing.assert_allclose(gp[1], d[1], atol=1e-9)
    # PR: no kernel (eq. 3.25 with a Gaussian prior) against ridge regression in closed form
    hp_pr = Hyperparameters(hp.log_sigma_w, np.log([0.1, 0.1]), (np.zeros(0), np.zeros(0)))
    pr = fit_posterior([None, None], U, Y, F, hp_pr)
    A = np.concatenate([F[:, 0], F[:, 1]])
    y = np.concatenate([Y[:, 0], Y[:, 1]])
    w = np.linalg.solve(A.T @ A + (0.1**2 / np.exp(2 * hp.log_sigma_w)) * np.eye(3), A.T @ y)
    np.testing.assert_allclose(pr.w_mean, w, rtol=1e-9)


def test_sparse_equals_exact_when_inducing_points_are_the_data():
    U, Y, F, kernels, hp, Uq, Fq = _tiny(seed=2)
    exact = fit_posterior(kernels, U, Y, F, hp)
    sparse = fit_posterior(kernels, U, Y, F, hp, inducing=U.copy())
    for a, b in zip(exact.predict(Uq, Fq), sparse.predict(Uq, Fq), strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(exact.log_likelihood, sparse.log_likelihood, rtol=1e-6)
    np.testing.assert_allclose(exact.w_mean, sparse.w_mean, rtol=1e-5, atol=1e-6)


def test_sparse_with_few_inducing_points_is_an_approximation():
    U, Y, F, kernels, hp, Uq, Fq = _tiny(seed=3, N=40)
    exact = fit_posterior(kernels, U, Y, F, hp).predict(Uq, Fq)
    sparse = fit_posterior(kernels, U, Y, F, hp, inducing=U[:5]).predict(Uq, Fq)
    assert not np.allclose(exact[0], sparse[0], atol=1e-6)  # the test above is not vacuous
    assert np.all(sparse[1] >= 0)


def test_sparse_log_likelihood_is_the_vfe_lower_bound():
    """Titsias's bound: below the exact log likelihood with few inducing inputs, and the value
    the sparse negative_log_likelihood (the learning objective) returns."""
    from diegocal.sgp.gp import negative_log_likelihood

    U, Y, F, kernels, hp, Uq, Fq = _tiny(seed=4, N=40)
    exact = fit_posterior(kernels, U, Y, F, hp).log_likelihood
    sparse = fit_posterior(kernels, U, Y, F, hp, inducing=U[:6]).log_likelihood
    assert sparse < exact
    sizes = [k.n_params for k in kernels]
    nll = negative_log_likelihood(hp.pack(), kernels, U, Y, F, sizes, grad=False, inducing=U[:6])
    np.testing.assert_allclose(-nll, sparse, rtol=1e-12)


def test_failed_cholesky_raises_numerical_error_with_a_hint():
    import pytest

    from diegocal.errors import NumericalError
    from diegocal.sgp.blocks import cholesky

    with pytest.raises(NumericalError, match="min_noise"):
        cholesky(-np.eye(3), "test matrix")
    L, jitter = cholesky(np.ones((4, 4)), "rank-one matrix")  # repeated inputs: jitter rescues it
    assert jitter > 0 and np.allclose(L @ L.T, np.ones((4, 4)), atol=1e-3)


def _w_spread(rho: float, reps: int = 500, N: int = 400):
    """PR of a constant and a slow sine under noise of std 0.1, AR(1) coefficient ``rho``:
    the spread of ŵ over ``reps`` draws (the truth), and the mean of eq. (3.20)'s and the
    robust variance of ŵ."""
    rng = np.random.default_rng(3)
    t = np.arange(N) * 0.02
    F = np.stack([np.ones(N), np.sin(0.7 * t)], axis=1)[:, None, :]  # (N, 1, 2)
    hp = Hyperparameters(np.log(10.0), np.log([0.1]), (np.zeros(0),))
    w, model, robust = [], [], []
    for _ in range(reps):
        e = lfilter([np.sqrt(1 - rho**2)], [1.0, -rho], rng.standard_normal(N), zi=[rho * rng.standard_normal()])[0]
        y = F[:, 0] @ np.array([1.0, 0.5]) + 0.1 * e
        post = fit_posterior([None], t[:, None], y[:, None], F, hp)
        w.append(post.w_mean)
        model.append(np.diag(post.w_cov))
        robust.append(np.diag(post.w_cov_robust))
    return np.var(w, axis=0), np.mean(model, axis=0), np.mean(robust, axis=0)


def test_robust_w_covariance_follows_the_spread_of_w_when_the_residual_is_correlated():
    """Ground truth by Monte Carlo: under white noise eq. (3.20)'s M⁻¹ and the cluster-robust
    covariance both match ŵ's spread (robust/truth 0.94, 0.80 over 500 draws: 10 blocks, residuals
    shrunk by the fit); under a residual correlated over many samples (AR(1), 0.9 and 0.98 per
    20 ms sample: what an unmodelled effect leaves) M⁻¹ is 15-100 times too small and the robust
    one within a factor of two of the truth while a block is four correlation times long or more
    (0.56-0.80; at 0.98 with 400 samples, blocks under one correlation time long, it is 0.2)."""
    truth, model, robust = _w_spread(0.0)
    assert np.all((model / truth > 0.75) & (model / truth < 1.33)), (model, truth)
    assert np.all((robust / truth > 0.5) & (robust / truth < 1.5)), (robust, truth)
    for rho, N in ((0.9, 400), (0.98, 2000)):
        truth, model, robust = _w_spread(rho, N=N)
        assert np.all(model / truth < 0.1), (rho, model, truth)
        assert np.all((robust / truth > 0.5) & (robust / truth < 2.0)), (rho, robust, truth)


def test_robust_variance_is_only_for_outputs_without_a_gp_and_only_raises_the_variance():
    U, Y, F, kernels, hp, Uq, Fq = _tiny(seed=2, N=40)
    assert fit_posterior(kernels, U, Y, F, hp).w_cov_robust is None  # every output has a GP
    mixed = [kernels[0], None]
    hp_mixed = Hyperparameters(hp.log_sigma_w, hp.log_sigma_v, (hp.theta[0], np.zeros(0)))
    robust = fit_posterior(mixed, U, Y, F, hp_mixed)
    plain = fit_posterior(mixed, U, Y, F, hp_mixed, robust=False)
    assert robust.w_cov_robust is not None and plain.w_cov_robust is None
    m_r, v_r, _ = robust.predict(Uq, Fq)
    m_p, v_p, _ = plain.predict(Uq, Fq)
    np.testing.assert_array_equal(m_r, m_p)
    assert np.all(v_r >= v_p) and np.any(v_r > v_p)
