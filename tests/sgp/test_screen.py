"""ML-II's starts screened on a few samples, the best refined on all (SemiParametricGP._screen): the
refined optimum is as good as the best of the starts run on every sample, held out too, and
the parameters W are the truth's."""

import numpy as np
import pytest

import diegocal.sgp.estimator as estimator
import diegocal.sgp.starts as starts
from diegocal.sgp.kernels import SquaredExponential


def _run(N, seed, t0=0.0):
    """(U (N, 2), Y (N, 1), F (N, 1, 2), clean Y): a linear model in u_1 plus a bump in u_2 it
    does not have, 50 Hz samples of a smooth trajectory from time t0, noise 0.05."""
    t = t0 + np.arange(N) / 50.0
    U = np.column_stack([np.sin(0.7 * t), np.cos(1.1 * t + 0.3)])
    F = np.column_stack([U[:, 0], np.ones(N)])[:, None, :]
    clean = 1.5 * U[:, 0] + 0.3 + 0.4 * np.exp(-(((U[:, 1] - 0.5) / 0.3) ** 2))
    y = clean + 0.05 * np.random.default_rng(seed).normal(size=N)
    return U, y[:, None], F, clean


def _fit(data, screen: bool, sizes: list):
    """The SGP of two starts' more than the first (restarts=2), screened or not; ``sizes``
    collects the sample count of each ML-II run."""
    sizes.clear()
    gp = estimator.SemiParametricGP([SquaredExponential(2)], restarts=2, screen_starts=screen)
    return gp.fit(*data), list(sizes)


def test_screened_starts_reach_the_full_starts_optimum(monkeypatch):
    U, Y, F, _ = _run(700, seed=5)
    Uq, _, Fq, clean = _run(400, seed=6, t0=30.0)
    sizes = []
    optimise = estimator.SemiParametricGP._optimise

    def recorded(self, start, bounds, sizes_, resid, U, *rest):
        sizes.append(len(U))
        return optimise(self, start, bounds, sizes_, resid, U, *rest)

    monkeypatch.setattr(estimator.SemiParametricGP, "_optimise", recorded)
    screened, runs = _fit((U, Y, F), True, sizes)
    assert runs == [starts.SCREEN_SAMPLES] * 3 + [700], "three starts screened, one refined"
    full, runs = _fit((U, Y, F), False, sizes)
    assert runs == [700] * 3
    # the same likelihood (−log p on the same 700 samples) to a nat
    assert screened.objective_ <= full.objective_ + 1.0
    err = [np.mean((gp.predict(Uq, Fq, variance=False)[0][:, 0] - clean) ** 2) for gp in (screened, full)]
    assert err[0] <= 1.05 * err[1]
    bump = 0.4 * np.exp(-(((Uq[:, 1] - 0.5) / 0.3) ** 2))
    assert err[0] < 0.1 * np.mean(bump**2), "the bump must be learnt"
    np.testing.assert_allclose(screened.w_, [1.5, 0.3], atol=0.1)  # W, the parametric part's truth


@pytest.mark.parametrize("jobs", [1, 2])
def test_screen_orders_the_screened_optima_best_first_then_the_failed_starts(monkeypatch, jobs):
    """Start i (its first entry) screens to ``outcome[i]``: (objective, its optimum's first entry)
    or a failure (None); ties go to the earlier start, whatever the thread count."""
    outcome = {0: (5.0, 100.0), 1: None, 2: (-3.0, 102.0), 3: (-3.0, 103.0), 4: (1.0, 104.0)}
    sizes = []

    def fake(self, start, bounds, sizes_, resid, U, *rest):
        sizes.append(len(U))
        got = outcome[int(start[0])]
        return None if got is None else (got[0], np.array([got[1]]))

    monkeypatch.setattr(estimator.SemiParametricGP, "_optimise", fake)
    gp = estimator.SemiParametricGP([SquaredExponential(1)], jobs=jobs)
    data = (np.zeros((600, 1)), np.zeros((600, 1)), np.zeros((600, 1, 0)))
    order = gp._screen([np.array([float(i)]) for i in range(5)], None, None, None, data)
    assert [float(x[0]) for x in order] == [102.0, 103.0, 104.0, 100.0, 1.0]
    assert sizes == [starts.SCREEN_SAMPLES] * 5


def test_a_failed_refinement_falls_back_to_the_next_screened_start(monkeypatch):
    U, Y, F, _ = _run(520, seed=7)
    runs = []
    optimise = estimator.SemiParametricGP._optimise

    def first_refinement_fails(self, start, bounds, sizes, resid, U, *rest):
        runs.append(len(U))
        if len(U) > starts.SCREEN_SAMPLES and runs.count(len(U)) == 1:
            return None
        return optimise(self, start, bounds, sizes, resid, U, *rest)

    monkeypatch.setattr(estimator.SemiParametricGP, "_optimise", first_refinement_fails)
    gp, _ = _fit((U, Y, F), True, [])
    assert runs == [starts.SCREEN_SAMPLES] * 3 + [520, 520]
    assert np.isfinite(gp.objective_)
