"""Only each family's best variant written (diegocal/diagnose/kinematics_families.py): the
selection tests the same candidates, with the same numbers, as when every variant is written."""

from __future__ import annotations

import numpy as np
import pytest

from diegocal.diagnose.kinematics import KinematicsAdapter
from diegocal.diagnose.kinematics_families import FamilyRanks
from diegocal.diagnose.selection import _candidate_channels, _fit, _Stack, channel_weights, evaluate_candidates
from diegocal.diagnose.types import EngineOptions
from diegocal.evaluate import split_blocks
from diegocal.robot import load_robot, resolve_robot_dir
from diegocal.sim.effects import parse_effect
from diegocal.sim.kinematics import KinematicsOptions, simulate_kinematics
from diegocal.terms import Region, make_term


@pytest.fixture(scope="module")
def slipped():
    """A finger log with a backlash, fitted with a marker slip half-way (a slipped marker's rows
    are its second marker's from the slip on), some readings written off."""
    finger = load_robot(resolve_robot_dir("finger", None))
    opts = KinematicsOptions(duration=20.0, effects=(parse_effect("backlash"),))
    log = simulate_kinematics(finger, opts, np.random.default_rng(5))
    blocks = split_blocks(log.n_samples, 10)
    train, val = blocks.mask("train"), blocks.mask("validation")
    adapter = KinematicsAdapter(log, finger)
    marker = adapter.marker_names[1]
    slip = make_term("marker_slip", marker, region=Region("time", float(adapter.time[log.n_samples // 2]), np.inf))
    fitted = adapter.fit((slip,), train)
    assert fitted.applied.slips
    res = adapter.residuals(fitted)
    rng = np.random.default_rng(0)
    exclude = {marker: rng.random(log.n_samples) < 0.05, adapter.pot_names[2]: rng.random(log.n_samples) < 0.05}
    return adapter, fitted, res, train, val, exclude


def _tested(adapter, fitted, res, train, val, exclude, ranked: bool):
    weights = channel_weights(res, train)
    adapter.selection_weights = weights if ranked else None
    adapter.selection_exclude = exclude if ranked else None
    cands = adapter.candidates(fitted, res, train)
    return cands, evaluate_candidates(cands, res, weights, train, val, EngineOptions(), exclude)


def test_the_selection_tests_the_same_variants(slipped):
    every, want = _tested(*slipped, ranked=False)
    held, got = _tested(*slipped, ranked=True)
    families = {c.family for c in every if c.family.startswith(("backlash", "time_offset"))}
    assert len(families) > 4
    assert len(held) <= len(every) - 4 * len(families)  # most variants never written
    assert [t.term.label for t in got] == [t.term.label for t in want]
    for a, b in zip(got, want, strict=True):
        assert a.term.extra == b.term.extra
        assert a.test.t == pytest.approx(b.test.t, rel=1e-9)
        np.testing.assert_allclose(a.term.values, b.term.values, rtol=1e-9)


def test_each_variants_gain_from_sums_is_the_selections(slipped, monkeypatch):
    """Every ranked variant's training gain from the sweep's sums equals the selection's own fit
    of its written columns (float32 against float64: to 1e-5 of the family's energy), with the
    readings written off and a slipped marker's rows its second marker's from the slip on."""
    adapter, fitted, res, train, val, exclude = slipped
    seen = {}

    def record(self, rows, maps):
        seen.update(self.gains(rows, maps))
        return set()  # every variant written

    monkeypatch.setattr(FamilyRanks, "dropped", record)
    cands, _ = _tested(*slipped, ranked=True)
    ranked = [c for c in cands if c.family.startswith(("backlash", "time_offset"))]
    assert len(ranked) == len(seen) > 20
    weights = channel_weights(res, train)
    stack = _Stack(res, weights, np.flatnonzero(train), exclude)
    for cand, i in zip(ranked, sorted(seen), strict=True):
        gain, energy = seen[i]
        fit = _fit(cand, stack, _candidate_channels(cand))
        assert abs(gain - fit.train_gain) <= 1e-5 * energy, cand.term.label
