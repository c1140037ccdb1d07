"""Binned candidates keep a bin index per sample and build their one-hot columns when read
(issue #33: every channel × variable of a long log tested in one round): the columns read are
the indicator columns of the bins, NaN where the variable is missing."""

import numpy as np
import pytest

from diegocal.diagnose.show import binned_candidate, flexible_candidate
from diegocal.diagnose.types import Residuals


def _residuals(T=300, seed=0):
    rng = np.random.default_rng(seed)
    x, z = rng.uniform(-1, 1, T), rng.normal(size=T)
    x[[5, 77]] = np.nan
    channels = {"j": rng.normal(size=T), "m": rng.normal(size=(T, 3))}
    return Residuals(
        channels,
        {"j": "N·m", "m": "m"},
        {"x": x, "z": z},
        {"j": ("x",), "m": ("x",)},
        {"j": ("z",)},
    )


def _indicators(x, edges):
    """The expected columns, written out: 1 where x falls in [edges[k], edges[k+1]) (the ends
    open), NaN rows where x is missing."""
    B = edges.size - 1
    out = np.zeros((x.size, B))
    for t, v in enumerate(x):
        if not np.isfinite(v):
            out[t] = np.nan
            continue
        k = int(np.searchsorted(edges, v, side="right")) - 1
        out[t, min(max(k, 0), B - 1)] = 1.0
    return out


def test_binned_columns_are_the_bins_indicators_on_each_axis():
    res = _residuals()
    train = np.arange(300) < 200
    cand = binned_candidate(res, "j", "x", train, 8)
    edges = np.asarray(cand.term.extra["edges"])
    expected = _indicators(res.variables["x"], edges)
    assert list(cand.columns) == ["j"] and "m" not in cand.columns and cand.columns.get("m") is None
    np.testing.assert_array_equal(cand.columns["j"], expected)
    assert cand.n_params == expected.shape[1]
    assert cand.columns["j"] is not cand.columns["j"]  # built when read, not held
    assert all(b.dtype.itemsize <= 2 for b, _ in cand.columns.index)  # held: 2 bytes per sample
    axes = binned_candidate(res, "m", "x", train, 8).columns["m"]  # (T, 3, 3 B): one block per axis
    B = expected.shape[1]
    assert axes.shape == (300, 3, 3 * B)
    for a in range(3):
        np.testing.assert_array_equal(axes[:, a, a * B : (a + 1) * B], expected)
        others = np.delete(axes[:, a], np.s_[a * B : (a + 1) * B], axis=1)
        assert np.all(others == 0)


def test_flexible_columns_are_a_constant_and_each_variables_bins_but_the_first():
    res = _residuals(seed=1)
    train = np.arange(300) < 200
    cand = flexible_candidate(res, "j", train, 6)
    X = cand.columns["j"]
    parts = [np.ones((300, 1))]
    for v in ("x", "z"):
        parts.append(_indicators(res.variables[v], np.asarray(cand.term.extra["edges"][v]))[:, 1:])
    expected = np.hstack(parts)
    rows = np.isfinite(res.variables["x"])
    np.testing.assert_array_equal(X[rows], expected[rows])
    assert np.isnan(X[~rows]).any(axis=1).all()  # a missing variable leaves its rows out of every fit
    assert X.shape[1] == cand.n_params


def test_rows_asked_for_are_built_alone_and_equal_the_whole_columns_rows():
    res = _residuals(seed=2)
    train = np.arange(300) < 200
    some = np.flatnonzero(~train)[::3]
    for cand in (binned_candidate(res, "m", "x", train, 5), flexible_candidate(res, "j", train, 4)):
        (channel,) = cand.columns
        np.testing.assert_array_equal(cand.columns.rows(channel, some), cand.columns[channel][some])


def test_asking_whether_a_channel_is_there_builds_nothing(monkeypatch):
    res = _residuals(seed=3)
    cols = binned_candidate(res, "j", "x", np.arange(300) < 200, 5).columns
    monkeypatch.setattr(type(cols), "_onehot", lambda *a, **k: pytest.fail("columns built"))
    assert "j" in cols and "m" not in cols and list(cols) == ["j"]


def test_a_common_cause_joins_its_members_columns_when_read():
    """One cause on two channels tested as one: its columns are each member's on its own
    parameters, zero elsewhere, built when read (the rows of a fit alone for a fit)."""
    from diegocal.diagnose.selection import common_candidates, evaluate_candidates
    from diegocal.diagnose.types import Candidate, EngineOptions
    from diegocal.terms import Parameter, Term

    rng = np.random.default_rng(4)
    T = 400
    x = {c: rng.normal(size=(T, 2)) for c in ("a", "b")}
    res = Residuals({c: x[c] @ [1.0, -0.5] + 0.1 * rng.normal(size=T) for c in x}, dict.fromkeys(x, "N·m"))
    cands = [Candidate(Term("spring", c, (Parameter("k1"), Parameter("k2"))), {c: x[c]}) for c in x]
    train, val = np.arange(T) < 240, np.arange(T) >= 240
    tested = evaluate_candidates(cands, res, {"a": 1.0, "b": 1.0}, train, val, EngineOptions())
    (common,) = common_candidates(tested)
    cols = common.columns
    assert sorted(cols) == ["a", "b"] and "c" not in cols and common.n_params == 4
    first = [t.term.channel for t in common.members].index("a")
    expected = np.zeros((T, 4))
    expected[:, 2 * first : 2 * first + 2] = x["a"]
    np.testing.assert_array_equal(cols["a"], expected)
    rows = np.flatnonzero(train)
    np.testing.assert_array_equal(cols.rows("a", rows), expected[rows])


def test_common_causes_tested_beside_the_winners_equal_testing_all_again():
    """``evaluate_candidates(commons, alongside=tested)`` keeps the winners' fits and tests and
    gives them the thresholds of the larger family count: the same as fitting them all again. The
    candidates include a term named on one channel that acts more on another (its own-channel gain
    differs from its gain over all) and effects near ``min_gain``."""
    from dataclasses import replace

    from diegocal.diagnose.selection import common_candidates, evaluate_candidates
    from diegocal.diagnose.types import Candidate, EngineOptions
    from diegocal.terms import Parameter, Term

    rng = np.random.default_rng(11)
    T = 600
    chans = ("a", "b", "c", "d")
    x = {c: rng.normal(size=(T, 2)) for c in chans}
    size = {"a": 0.6, "b": 0.25, "c": 0.12, "d": 0.05}
    y = {c: size[c] * (x[c] @ [1.0, -0.5]) + 0.3 * rng.normal(size=T) for c in chans}
    z = rng.normal(size=T)
    y["m"] = 0.4 * z + 0.3 * rng.normal(size=T)
    y["a"] = y["a"] + 0.05 * z
    res = Residuals(y, dict.fromkeys(y, "N·m"))
    cands = [Candidate(Term("spring", c, (Parameter("k1"), Parameter("k2"))), {c: x[c]}) for c in chans]
    cands.append(Candidate(Term("payload", "a", (Parameter("m"),)), {"a": 0.05 * z[:, None], "m": 0.4 * z[:, None]}))
    train, val = np.arange(T) % 3 == 0, np.arange(T) % 3 == 1
    weights = dict.fromkeys(y, 1.0)
    for min_gain in (0.02, 0.05, 0.2):
        options = replace(EngineOptions(), min_gain=min_gain)
        tested = evaluate_candidates(cands, res, weights, train, val, options)
        commons = common_candidates(tested)
        assert commons
        again = evaluate_candidates([t.candidate for t in tested] + commons, res, weights, train, val, options)
        beside = evaluate_candidates(commons, res, weights, train, val, options, alongside=tested)
        assert [t.term.label for t in beside] == [t.term.label for t in again]
        for b, a in zip(beside, again, strict=True):
            assert (b.threshold, b.significant, b.gain, b.channel_gain, b.own_gain) == (
                a.threshold, a.significant, a.gain, a.channel_gain, a.own_gain
            )
            np.testing.assert_array_equal(b.term.values, a.term.values)
        assert any(t.own_gain is not None and t.own_gain != t.gain for t in again)
