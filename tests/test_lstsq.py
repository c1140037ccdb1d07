"""Least squares a chunk of rows at a time (diegocal.lstsq) against numpy's lstsq on the whole."""

import numpy as np
import pytest

from diegocal.lstsq import UPDATE_ROWS, TallLstsq


def _chunked(X, y, sizes):
    ls = TallLstsq(X.shape[1])
    at = 0
    for m in sizes:
        ls.add(X[at : at + m], y[at : at + m])
        at += m
    return ls


@pytest.mark.parametrize("sizes", [(500,), (3, 0, 97, 400), (250, 250)])
def test_chunks_give_lstsq_solution_residual_and_gram(sizes):
    rng = np.random.default_rng(1)
    X = rng.standard_normal((500, 6)) * np.array([1.0, 10.0, 0.1, 1e3, 1.0, 5.0])
    y = X @ rng.standard_normal(6) + 0.1 * rng.standard_normal(500)
    ls = _chunked(X, y, sizes)
    w, rss = ls.solve()
    w0 = np.linalg.lstsq(X, y, rcond=None)[0]
    np.testing.assert_allclose(w, w0, rtol=1e-11, atol=1e-12)
    np.testing.assert_allclose(rss, float(np.sum((y - X @ w0) ** 2)), rtol=1e-9)
    np.testing.assert_allclose(ls.gram(), X.T @ X, rtol=1e-10, atol=1e-8)
    assert ls.rows == 500


def test_a_rank_deficient_system_gets_the_minimum_norm_solution():
    rng = np.random.default_rng(2)
    a = rng.standard_normal((300, 3))
    X = np.column_stack([a, a[:, 0]])  # the last column repeats the first
    y = rng.standard_normal(300)
    w, _ = _chunked(X, y, (100, 200)).solve()
    np.testing.assert_allclose(w, np.linalg.lstsq(X, y, rcond=None)[0], rtol=1e-9, atol=1e-12)
    assert w[0] == pytest.approx(w[3])


def test_a_chunk_longer_than_one_update_gives_the_same_factor():
    rng = np.random.default_rng(3)
    X = rng.standard_normal((2 * UPDATE_ROWS + 77, 5))
    y = X @ rng.standard_normal(5) + rng.standard_normal(len(X))
    whole, parts = _chunked(X, y, (len(X),)), _chunked(X, y, (UPDATE_ROWS - 1, 2, len(X) - UPDATE_ROWS - 1))
    R0 = np.linalg.qr(np.column_stack([X, y]), mode="r")
    for ls in (whole, parts):
        np.testing.assert_allclose(np.abs(ls.R), np.abs(R0), rtol=1e-10, atol=1e-10)  # rows' signs are free
        np.testing.assert_allclose(ls.solve()[0], np.linalg.lstsq(X, y, rcond=None)[0], rtol=1e-11)
