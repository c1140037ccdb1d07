"""The Woodbury route equals the dense route (thesis eq. 3.8-3.20), and sparse equals exact
when the inducing inputs are the data."""

import numpy as np
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
    from diegocal.sgp.gp import cholesky

    with pytest.raises(NumericalError, match="min_noise"):
        cholesky(-np.eye(3), "test matrix")
    L, jitter = cholesky(np.ones((4, 4)), "rank-one matrix")  # repeated inputs: jitter rescues it
    assert jitter > 0 and np.allclose(L @ L.T, np.ones((4, 4)), atol=1e-3)
