"""Analytic marginal-likelihood gradients equal central finite differences (all hyperparameters)."""

import numpy as np
import pytest

from diegocal.sgp.gp import Hyperparameters, negative_log_likelihood
from diegocal.sgp.kernels import REGION_OFF, Constant, Kernel, Region, SquaredExponential, Subspace


def _problem(n_out=2, N=25, p=3, m=4, seed=0):
    rng = np.random.default_rng(seed)
    U = rng.standard_normal((N, p))
    F = rng.standard_normal((N, n_out, m))
    Y = F @ rng.standard_normal(m) + np.sin(U[:, :1] * 2) + 0.1 * rng.standard_normal((N, n_out))
    return U, Y, F, rng


def _check(kernels, U, Y, F, rng, inducing=None):
    sizes = [0 if k is None else k.n_params for k in kernels]
    theta = tuple(rng.normal(0, 0.4, s) for s in sizes)
    hp = Hyperparameters(0.3, np.log([0.2, 0.3][: Y.shape[1]]), theta)
    x = hp.pack()
    f, g = negative_log_likelihood(x, kernels, U, Y, F, sizes, inducing=inducing)
    eps = 1e-5
    fd = np.zeros_like(x)
    for i in range(x.size):
        e = np.zeros_like(x)
        e[i] = eps
        fd[i] = (
            negative_log_likelihood(x + e, kernels, U, Y, F, sizes, grad=False, inducing=inducing)
            - negative_log_likelihood(x - e, kernels, U, Y, F, sizes, grad=False, inducing=inducing)
        ) / (2 * eps)
    np.testing.assert_allclose(g, fd, rtol=1e-5, atol=1e-6 * max(1.0, abs(f)))
    return g


def test_sgp_gradient_matches_finite_differences():
    U, Y, F, rng = _problem()
    kernels = [Subspace([0, 2], SquaredExponential(2)), SquaredExponential(3)]
    g = _check(kernels, U, Y, F, rng)
    assert g.size == 1 + 2 + 3 + 4 and np.all(np.abs(g) > 0)  # σ_w, σ_v×2, kernels all move


def test_gp_gradient_matches_finite_differences():
    U, Y, F, rng = _problem()
    _check([SquaredExponential(3), SquaredExponential(3)], U, Y, F[:, :, :0], rng)


def test_pr_gradient_matches_finite_differences():
    U, Y, F, rng = _problem()
    _check([None, None], U, Y, F, rng)


@pytest.mark.parametrize("features", [True, False])
def test_sparse_vfe_gradient_matches_finite_differences(features):
    """The VFE bound (inducing inputs fixed) has an analytic gradient too; one output has no GP."""
    U, Y, F, rng = _problem()
    kernels = [Subspace([0, 2], SquaredExponential(2)), None] if features else [SquaredExponential(3)] * 2
    Z = U[rng.choice(len(U), 6, replace=False)] + 0.1 * rng.standard_normal((6, 3))
    _check(kernels, U, Y, F if features else F[:, :, :0], rng, inducing=Z)


@pytest.mark.parametrize("compose", ["sum", "product", "region"])
def test_composite_kernel_gradient(compose):
    U, Y, F, rng = _problem(n_out=1)
    a, b = Subspace([0], SquaredExponential(1)), Subspace([1, 2], SquaredExponential(2))
    k = {"sum": a + Constant(), "product": a * b, "region": Region(2, a * b)}[compose]
    _check([k], U, Y, F, rng)


def test_region_kernel_is_its_base_when_off_and_cut_in_two_when_sharp():
    """Off (onset above every input) the Region kernel is k_0 exactly; with a hard step the
    covariance across the onset is 0 and the side above is k_0 scaled by r²."""
    rng = np.random.default_rng(4)
    X = rng.standard_normal((40, 3))
    base = Subspace([0, 2], SquaredExponential(2))
    t0 = rng.normal(0, 0.4, base.n_params)
    region = Region(1, base)
    K0 = base(X, X, t0)
    off = np.concatenate([[REGION_OFF, np.log(0.02), 0.7], t0])
    np.testing.assert_array_equal(region(X, X, off), K0)
    np.testing.assert_array_equal(region.diag(X, off), base.diag(X, t0))
    sharp = np.concatenate([[0.1, np.log(1e-9), np.log(3.0)], t0])
    above = X[:, 1] >= 0.1
    K = region(X, X, sharp)
    np.testing.assert_allclose(K[np.ix_(above, ~above)], 0.0, atol=1e-300)
    np.testing.assert_allclose(K[np.ix_(above, above)], 9.0 * K0[np.ix_(above, above)], rtol=1e-12)
    np.testing.assert_allclose(K[np.ix_(~above, ~above)], K0[np.ix_(~above, ~above)], rtol=1e-12)


def _kernel_zoo():
    se = SquaredExponential(3)
    sub = Subspace([0, 2], SquaredExponential(2))
    return {
        "se": se,
        "subspace": sub,
        "sum": sub + Constant(),
        "product": Subspace([0], SquaredExponential(1)) * Subspace([1, 2], SquaredExponential(2)),
        "region": Region(1, sub),
    }


@pytest.mark.parametrize("name", ["se", "subspace", "sum", "product", "region"])
def test_weighted_gradient_equals_dense_contraction(name):
    """Σ_ab W_ab ∂K_ab/∂θ_p: the closed form equals contracting the dense derivatives (X1 = X2)
    and central finite differences of Σ W ∘ k(X1, X2) (cross-covariances, sparse inference);
    likewise its diagonal form."""
    k = _kernel_zoo()[name]
    rng = np.random.default_rng(3)
    X, Z = rng.standard_normal((30, 3)), rng.standard_normal((7, 3))
    theta = rng.normal(0, 0.4, k.n_params)
    W = rng.standard_normal((30, 30))
    W = W + W.T
    dense = np.array([np.sum(W * dK) for dK in k.gradients(X, theta)])
    np.testing.assert_allclose(k.weighted_gradient(X, X, theta, W), dense, rtol=1e-10, atol=1e-10)
    Wc = rng.standard_normal((30, 7))
    eps, fd = 1e-6, np.zeros(k.n_params)
    for p in range(k.n_params):
        e = np.zeros(k.n_params)
        e[p] = eps
        fd[p] = np.sum(Wc * (k(X, Z, theta + e) - k(X, Z, theta - e))) / (2 * eps)
    np.testing.assert_allclose(k.weighted_gradient(X, Z, theta, Wc), fd, rtol=1e-6, atol=1e-8)
    w = rng.standard_normal(30)  # Σ_a w_a ∂k(x_a, x_a): closed form vs the dense 1×1 derivatives
    np.testing.assert_allclose(
        k.weighted_diag_gradient(X, theta, w), Kernel.weighted_diag_gradient(k, X, theta, w), atol=1e-12
    )
