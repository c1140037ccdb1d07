"""diegocal.evaluate: contiguous blocks with roles, one score type, the one-standard-error rule."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from diegocal.evaluate import block_mse, choose_by_validation, paired_se, score, split_blocks, sub_blocks


@given(st.integers(2, 5000), st.integers(1, 40))
def test_blocks_cover_every_sample_once_in_time_order(n, k):
    b = split_blocks(n, k)
    assert b.edges[0] == 0 and b.edges[-1] == n
    assert np.all(np.diff(b.edges) >= 1)
    masks = [b.mask(r) for r in ("train", "validation", "heldout")]
    assert np.array_equal(sum(m.astype(int) for m in masks), np.ones(n, int))
    labels = b.labels()
    assert np.all(np.diff(labels) >= 0)


def test_roles_are_interleaved_over_the_session():
    b = split_blocks(1000, 10)
    assert b.roles.count("train") == 6 and b.roles.count("validation") == 2 and b.roles.count("heldout") == 2
    held = b.index("heldout")
    assert held.min() < 500 < held.max()  # held-out blocks early and late in the session


def test_sub_blocks_never_span_a_gap():
    mask = np.zeros(100, bool)
    mask[10:30] = mask[60:65] = True
    cl = sub_blocks(mask, 8)
    assert np.all(cl[~mask] == -1)
    assert set(cl[10:30]).isdisjoint(set(cl[60:65]))
    assert len(set(cl[10:30])) == 2  # 20 samples cut into pieces of about 8


def test_score_of_scalars_and_of_points():
    rng = np.random.default_rng(0)
    y = rng.normal(size=(500, 2))
    err = np.array([0.1, 0.25])
    s = score(y, y + err, ("a", "b"), std=np.full((500, 2), 0.1), unit="V")
    assert s.rmse == pytest.approx(err)
    assert s.mae == pytest.approx(err)
    assert s.coverage == pytest.approx([1.0, 0.0])  # |e| = 0.1 <= 2σ = 0.2 < 0.25
    x = rng.normal(size=(300, 3, 3))
    x[:50, 1] = np.nan  # occluded
    p = x + np.array([0.0, 0.0, 0.03])
    m = score(x, p, ("m0", "m1", "m2"), unit="m")
    assert m.rmse == pytest.approx([0.03] * 3)
    assert m.n_samples.tolist() == [300, 250, 300]
    masked = score(y, y + err, ("a", "b"), mask=np.arange(500) < 100)
    assert masked.n_samples.tolist() == [100, 100]


def test_block_mse_and_paired_se():
    labels = np.repeat(np.arange(4), 25)
    sq = np.repeat([1.0, 2.0, 3.0, 4.0], 25)
    assert block_mse(sq, labels) == pytest.approx([1, 2, 3, 4])
    mean, se = paired_se(np.array([2.0, 3.0, 4.0, 5.0]), np.array([1.0, 2.0, 3.0, 4.0]))
    assert mean == pytest.approx(1.0) and se == pytest.approx(0.0)


def test_one_standard_error_rule():
    """options (learnt, released, parametric) × 5 blocks × 3 outputs: the best option wins only
    when it beats the fallback by more than one standard error of the paired difference."""
    rng = np.random.default_rng(1)
    base = rng.uniform(1.0, 2.0, (5, 3))
    per_block = np.stack([base - [0.5, 0.01, 0.0], base - [0.0, 0.0, 0.0], base])
    per_block[0, :, 1] += [0.05, -0.05, 0.05, -0.05, 0.0]  # output 1: a gain of 0.01 ± 0.02 (one SE)
    assert choose_by_validation(per_block, fallback=2).tolist()[0] == 0
    assert choose_by_validation(per_block, fallback=2).tolist()[1:] == [2, 2]


def test_minimum_gain_keeps_the_fallback():
    """A consistent gain (every block, so far beyond one SE) smaller than ``min_gain`` of the
    fallback's error keeps the fallback; the same gain above it wins."""
    fallback = np.full((5, 2), 1.0)
    per_block = np.stack([fallback - [0.01, 0.05] + np.linspace(-1e-4, 1e-4, 5)[:, None], fallback])
    assert choose_by_validation(per_block, fallback=1).tolist() == [0, 0]
    assert choose_by_validation(per_block, fallback=1, min_gain=0.02).tolist() == [1, 0]
