"""Greedy conditional-variance inducing inputs (diegocal.sgp.inducing): they stop when the prior
variance they miss is small against the noise, and the sparse posterior is then the exact one."""

import numpy as np

from diegocal.sgp import SGPOptions, fit_dynamics
from diegocal.sgp.blocks import SparseBlock
from diegocal.sgp.gp import Hyperparameters, fit_posterior
from diegocal.sgp.inducing import greedy_inducing
from diegocal.sgp.kernels import SquaredExponential, Subspace


def _data(rng, N=600):
    U = rng.uniform(-2, 2, (N, 3))
    y = np.sin(3 * U[:, 0]) * (U[:, 1] > 0) + 0.05 * rng.standard_normal(N)
    return U, y


def test_greedy_stops_at_the_tolerance_and_a_short_lengthscale_needs_more_points():
    rng = np.random.default_rng(0)
    U, _ = _data(rng)
    k = Subspace([0, 1], SquaredExponential(2))  # input 2 is not seen by the kernel
    noise = 0.05**2
    short = greedy_inducing(k, np.log([1.0, 0.2, 0.5]), U, noise, tolerance=0.01)
    long = greedy_inducing(k, np.log([1.0, 1.0, 1.0]), U, noise, tolerance=0.01)
    assert short.gap <= 0.01 and long.gap <= 0.01
    assert len(long.points) < len(short.points) < len(U)
    # the points are training inputs, and the gap measured on the data agrees with the selection's
    assert all(np.any(np.all(U == p, axis=1)) for p in short.points)
    blk = SparseBlock(k, U, np.log([1.0, 0.2, 0.5]), noise, short.points)
    assert blk.gap <= 0.01
    # an output whose GP is off (σ_z at its floor) needs one point
    off = greedy_inducing(k, np.log([1e-6, 0.2, 0.5]), U, noise, tolerance=0.01)
    assert len(off.points) == 1
    # the cap wins over the tolerance, and the gap says so
    capped = greedy_inducing(k, np.log([1.0, 0.2, 0.5]), U, noise, tolerance=0.01, max_points=10)
    assert len(capped.points) == 10 and capped.gap > 0.01


def test_sparse_posterior_at_the_tolerance_predicts_as_the_exact_one():
    rng = np.random.default_rng(1)
    U, y = _data(rng)
    Y, F = y[:, None], np.ones((len(U), 1, 1))
    kernels = [Subspace([0, 1], SquaredExponential(2))]
    hp = Hyperparameters(0.0, np.log([0.05]), (np.log([1.0, 0.3, 0.5]),))
    sel = greedy_inducing(kernels[0], hp.theta[0], U, 0.05**2, tolerance=0.01)
    Uq = rng.uniform(-2, 2, (200, 3))
    Fq = np.ones((200, 1, 1))
    exact = fit_posterior(kernels, U, Y, F, hp).predict(Uq, Fq)
    sparse = fit_posterior(kernels, U, Y, F, hp, [sel.points]).predict(Uq, Fq)
    diff = sparse[0] - exact[0]  # means, against a signal of amplitude 1 and noise std 0.05
    assert np.sqrt(np.mean(diff**2)) < 0.005 and np.max(np.abs(diff)) < 0.05
    np.testing.assert_allclose(np.sqrt(sparse[1]), np.sqrt(exact[1]), atol=0.02)
    few = fit_posterior(kernels, U, Y, F, hp, [sel.points[:10]]).predict(Uq, Fq)  # the check can fail
    assert np.sqrt(np.mean((few[0] - exact[0]) ** 2)) > 0.05


def test_progress_is_told_of_every_start_and_the_posterior(arm2, simulate):
    log, _ = simulate(arm2, T=120, seed=2)
    seen = []
    fit_dynamics(log, arm2, SGPOptions(kind="sgp", maxiter=20), progress=lambda *a: seen.append(a))
    starts = [a for a in seen if a[1].startswith("hyperparameter starts")]
    assert starts[0][2:] == (0, 3) and starts[-1][2:] == (3, 3)
    assert ("sgp", "posterior", 1, 1) in seen
    assert any(a[1].startswith("cross-validation") and a[2] == a[3] for a in seen)
