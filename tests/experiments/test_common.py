"""The experiment harness scores what it should: nMSE against the noise-free torque normalised by
its variance, coverage of the measured torque by mean ± 2σ, per region and joint."""

from __future__ import annotations

import numpy as np
import pytest

from diegocal.robot import load_robot
from diegocal.robot.model import BUNDLED_ROBOTS
from diegocal.sgp import TorquePrediction
from diegocal.sim.dynamics import DynamicsOptions, simulate_dynamics
from experiments.sgp.common import Score, score, select, spread_table, table


@pytest.fixture(scope="module")
def log():
    robot = load_robot(BUNDLED_ROBOTS / "arm3")
    return simulate_dynamics(robot, DynamicsOptions(duration=4.0, noise=0.05), np.random.default_rng(0))


def _pred(log, tau, std):
    z = np.zeros_like(tau)
    return TorquePrediction(log.streams["tau"].names, tau, np.broadcast_to(std, tau.shape), z, z)


def test_select_keeps_streams_and_truth_aligned(log):
    mask = np.arange(log.n_samples) % 3 == 0
    sub = select(log, mask)
    assert sub.n_samples == mask.sum()
    np.testing.assert_array_equal(sub.streams["q"].data, log.streams["q"].data[mask])
    np.testing.assert_array_equal(sub.truth.signals["tau"].data, log.truth.signals["tau"].data[mask])


def test_perfect_mean_and_wrong_predictions_score_as_expected(log):
    clean = log.truth.signals["tau"].data
    everywhere = {"all": np.ones(log.n_samples, bool)}
    perfect = score(_pred(log, clean, 0.05), log, everywhere, "x", 0, "perfect", "t")
    assert all(s.nmse == 0.0 for s in perfect)
    # 95 % interval with the true noise level covers ~95 % of measurements
    assert all(0.9 < s.coverage < 0.99 for s in perfect)
    mean = score(
        _pred(log, np.broadcast_to(clean.mean(0), clean.shape), 0.05),
        log,
        everywhere,
        "x",
        0,
        "m",
        "t",
    )
    np.testing.assert_allclose([s.nmse for s in mean], 1.0, rtol=1e-12)
    overconfident = score(_pred(log, clean + 0.2, 1e-3), log, everywhere, "x", 0, "o", "t")
    assert all(s.coverage < 0.05 for s in overconfident)


def test_regions_are_scored_separately_with_the_whole_log_variance(log):
    clean = log.truth.signals["tau"].data
    first = np.arange(log.n_samples) < log.n_samples // 2
    wrong = clean.copy()
    wrong[first] += 1.0
    s = score(_pred(log, wrong, 0.05), log, {"a": first, "b": ~first}, "x", 0, "m", "t")
    by = {(c.region, c.joint): c.nmse for c in s}
    var = clean.var(0)
    for j, joint in enumerate(log.streams["tau"].names):
        assert by[("a", joint)] == pytest.approx(1.0 / var[j])
        assert by[("b", joint)] == 0.0


def test_table_stars_the_best_method_per_row():
    rows = [Score("e", 0, m, "t", "r", "j", v, c, 10) for m, v, c in (("PR", 0.5, 0.5), ("SGP", 0.1, 0.9))]
    text = table(rows, "nmse")
    assert "0.1*" in text and "0.5*" not in text
    assert "0.9*" in table(rows, "coverage")


def _cells(values):
    """Scores of one cell: method -> nMSE per seed."""
    return [Score("e", k, m, "t", "r", "j", v, 0.9, 10) for m, vs in values.items() for k, v in enumerate(vs)]


def test_verdict_best_tied_and_worse_follow_the_paired_standard_error():
    from experiments.sgp.common import verdicts

    best = verdicts(_cells({"PR": [0.2, 0.3, 0.25], "SGP": [0.1, 0.2, 0.15]}))[0]
    assert best.label == "best" and best.best == "PR" and best.diff == pytest.approx(-0.1)
    # SGP behind by 0.01 on average, but the seeds disagree (one SE = 0.0265): tied
    tied = verdicts(_cells({"PR": [0.10, 0.20, 0.30], "SGP": [0.15, 0.16, 0.32]}))[0]
    assert tied.label == "tied" and tied.diff == pytest.approx(0.01) and tied.se > 0.01
    # behind on every seed by about the same amount: worse
    worse = verdicts(_cells({"PR": [0.10, 0.20, 0.30], "GP": [1, 1, 1], "SGP": [0.12, 0.21, 0.33]}))[0]
    assert worse.label == "worse" and worse.best == "PR"
    assert "worse (PR" in spread_table(_cells({"PR": [0.10, 0.20, 0.30], "SGP": [0.12, 0.21, 0.33]}))
