"""Subnormals flushed to zero while the SGP learns: on inside, off after, inherited by the jobs'
threads, and the likelihood the same (diegocal.sgp.subnormals)."""

import platform
import sys

import numpy as np
import pytest

import diegocal.sgp.estimator as estimator
from diegocal.parallel import thread_map
from diegocal.sgp import SGPOptions, fit_dynamics, subnormals
from diegocal.sgp.gp import negative_log_likelihood
from diegocal.sgp.kernels import SquaredExponential
from diegocal.sgp.subnormals import active, flushed

x86_linux = pytest.mark.skipif(
    sys.platform != "linux" or platform.machine() != "x86_64", reason="FTZ/DAZ is set on x86-64 Linux only"
)


@x86_linux
def test_flushed_inside_restored_after_and_inherited_by_worker_threads():
    assert not active()
    with flushed():
        assert active()
        with flushed():
            assert active()
        assert active()  # the inner exit restores the outer mode
        assert thread_map(lambda _: active(), range(4), jobs=2) == [True] * 4
    assert not active()
    assert thread_map(lambda _: active(), range(4), jobs=2) == [False] * 4


@x86_linux
def test_flushed_restores_the_mode_when_its_body_raises():
    with pytest.raises(ZeroDivisionError), flushed():
        assert active()
        _ = 1 / 0
    assert not active()


@x86_linux
@pytest.mark.parametrize("jobs", [1, 2])
def test_ml_ii_runs_flushed_and_the_fit_leaves_the_callers_mode(arm2, simulate, monkeypatch, jobs):
    log, _ = simulate(arm2, T=120, seed=3, bump=(1, 0.0, 1.0, 1.0))
    seen = []
    optimise = estimator.SemiParametricGP._optimise

    def recorded(self, *args):
        seen.append(active())
        return optimise(self, *args)

    monkeypatch.setattr(estimator.SemiParametricGP, "_optimise", recorded)
    fit_dynamics(log, arm2, SGPOptions(kind="sgp", maxiter=10, jobs=jobs))
    assert seen and all(seen), "every ML-II run, in every worker thread, must be flushed"
    assert not active()


@x86_linux
def test_a_short_length_scale_likelihood_is_the_same_flushed():
    """ℓ = 0.07 input stds on a smooth trajectory: some kernel entries and many of the factor's
    are subnormal without the flush (the case that was 10× slower); the likelihood and its
    gradient agree to rounding."""
    t = np.linspace(0.0, 60.0, 400)
    U = np.column_stack([np.sin(f * t + p) for f, p in [(0.3, 0.0), (0.5, 1.0), (0.7, 2.0)]])
    U = (U - U.mean(axis=0)) / U.std(axis=0)
    y = np.sin(3.0 * U[:, :1]) + 0.01 * np.random.default_rng(0).normal(size=(400, 1))
    kernel = SquaredExponential(3)
    vec = np.array([0.0, np.log(0.01), 0.0, *np.log([0.07, 0.07, 0.07])])
    K = kernel(U, U, vec[2:])
    assert np.any((K > 0) & (K < np.finfo(float).tiny)), "the case must hold subnormal entries"
    args = ([kernel], U, y, np.zeros((400, 1, 0)), [4])
    plain = negative_log_likelihood(vec, *args)
    with flushed():
        assert active()
        fast = negative_log_likelihood(vec, *args)
    assert fast[0] == pytest.approx(plain[0], rel=1e-12)
    np.testing.assert_allclose(fast[1], plain[1], rtol=1e-9, atol=1e-9 * np.abs(plain[1]).max())


@x86_linux
def test_the_probe_works_whatever_the_callers_underflow_setting():
    with np.errstate(under="raise"):
        assert subnormals._works()
        assert not active()
