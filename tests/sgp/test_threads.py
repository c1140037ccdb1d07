"""Threads: the fit is the same whatever the thread counts (issue #14: "same seed, same verdicts
on any thread count"), and the library runs BLAS on one thread whatever the caller set."""

import numpy as np
from threadpoolctl import threadpool_info, threadpool_limits

import diegocal.sgp.starts as starts
from diegocal.parallel import one_blas_thread, thread_map
from diegocal.sgp import SGPOptions, fit_dynamics


def _blas_threads() -> set:
    return {i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"}


def test_one_blas_thread_inside_and_the_callers_setting_after():
    with threadpool_limits(2, user_api="blas"):
        with one_blas_thread():
            assert _blas_threads() == {1}
        assert _blas_threads() == {2}


def test_thread_map_keeps_order_and_raises():
    assert thread_map(lambda x: x * x, range(7), jobs=3) == [x * x for x in range(7)]
    try:
        thread_map(lambda x: 1 / (x - 3), range(5), jobs=2)
    except ZeroDivisionError:
        pass
    else:
        raise AssertionError("the worker's exception must reach the caller")


def test_fit_is_identical_for_any_jobs_and_blas_threads(arm2, simulate, monkeypatch):
    monkeypatch.setattr(starts, "SCREEN_SAMPLES", 40)  # the starts screened too (150 > 2 × 40)
    log, _ = simulate(arm2, T=150, seed=3, bump=(1, 0.0, 1.0, 1.0))
    opts = SGPOptions(kind="sgp", maxiter=30, inference="sparse", n_inducing=40)
    base = fit_dynamics(log, arm2, opts)
    with threadpool_limits(2, user_api="blas"):  # the caller's setting: the library overrides it
        other = fit_dynamics(log, arm2, SGPOptions(**{**opts.to_dict(), "friction": opts.friction, "jobs": 2}))
    assert base.gp_.selection_ == other.gp_.selection_
    np.testing.assert_array_equal(base.gp_.hyper_.pack(), other.gp_.hyper_.pack())
    gps = [(base.gp_, other.gp_), (base.gp_.residual_, other.gp_.residual_)]  # joint, two stages
    gps = [(a, b) for a, b in gps if a is not None and a.inducing_ is not None]
    assert gps, "no GP kept: nothing to compare"  # the bump output keeps its GP (two stages)
    for est_a, est_b in gps:
        for a, b in zip(est_a.inducing_, est_b.inducing_, strict=True):
            np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(base.predict(log).tau, other.predict(log).tau)
