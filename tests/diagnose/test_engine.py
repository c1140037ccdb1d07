"""The diagnosis engine on a toy domain (tests/diagnose/toy.py) whose effects are known exactly:
it names what was hidden, finds nothing in clean data at the rate its statistics promise, and
measures the gain on held-out blocks only."""

from __future__ import annotations

import sys
from dataclasses import dataclass, replace
from functools import partial
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))
from toy import CHANNELS, ToyAdapter, make_data  # noqa: E402

from diegocal.diagnose.engine import EngineOptions, indistinguishable, run_unit, unplaced_span  # noqa: E402
from diegocal.diagnose.selection import choose, evaluate_candidates  # noqa: E402
from diegocal.diagnose.stats import out_of_sample_test  # noqa: E402
from diegocal.diagnose.types import Fault  # noqa: E402
from diegocal.evaluate import score, split_blocks  # noqa: E402
from diegocal.terms import Region, Term  # noqa: E402


def run(seed, effects, **kw):
    t, x, y = make_data(seed, effects=effects, **kw)
    return run_unit(ToyAdapter(t, x, y), split_blocks(len(t)), EngineOptions())


def test_a_hidden_bump_is_named_with_its_region_and_a_heldout_gain():
    d = run(0, [("bump", "c0", 0.5)])
    top = d.findings[0]
    assert (top.kind, top.cause, top.channel) == ("term", "bump", "c0")
    region = top.term.region
    assert region.low < 0.45 and region.high > 0.65  # the bump spans x in [0.4, 0.7]
    assert region.high - region.low < 0.8
    gain = top.gain()
    assert gain["reduction"] > 0.2 and gain["rmse_after"] < gain["rmse_before"]
    assert top.runners_up and all("validation_gain" in r for r in top.runners_up)
    assert "curves" in top.evidence and top.evidence["curves"]["before"]["count"]


def test_two_hidden_effects_are_both_found():
    d = run(3, [("bump", "c0", 0.5), ("quadratic", "c1", 0.4)])
    named = {(f.cause, f.channel) for f in d.findings}
    assert ("bump", "c0") in named
    assert ("square", "c1") in named or ("poly", "c1") in named


def test_a_finding_s_values_are_those_of_the_last_fit_with_every_term():
    """Two effects on one channel: the term found first has its values refitted beside the second,
    and diagnosis.yaml must print those, the extended model's (a user trial's spring on a UR10
    read 0.012398 ± 0.00012 where the saved model, with a torque offset beside it, held
    0.011654, the truth 0.011684)."""
    t, x, y = make_data(1, effects=[("bump", "c0", 0.4), ("quadratic", "c0", 0.8)])
    adapter = ToyAdapter(t, x, y)
    d = run_unit(adapter, split_blocks(len(t)), EngineOptions())
    terms = [f for f in d.findings if f.kind == "term" and f.channel == "c0"]
    assert len(terms) == 2, [f.term.label for f in d.findings]
    final = {u.label: u.values for u in adapter.terms(d.fitted)}
    for f in terms:
        np.testing.assert_array_equal(f.term.values, final[f.term.label])


def test_clean_data_gives_no_findings():
    for seed in range(5):
        d = run(100 + seed, [])
        assert d.findings == (), [f.term.label for f in d.findings]


@pytest.mark.parametrize("rho", [0.0, 0.9])
def test_the_out_of_sample_test_holds_its_level_on_correlated_noise(rho):
    """A correction fitted to pure noise on the training rows: at a nominal 10 % one-sided level,
    no more than about 10 % of 200 draws are significant (correlated noise included: the test
    sizes its sub-blocks from the residual's own correlation time)."""
    rng = np.random.default_rng(7)
    hits = 0
    n = 200
    T = 2000
    blocks = split_blocks(T)
    val = blocks.mask("validation")
    for _ in range(n):
        e = rng.normal(size=T)
        for k in range(1, T):
            e[k] += rho * e[k - 1]
        x = np.cumsum(rng.normal(size=T)) / 30
        train = blocks.mask("train")
        coef = np.polyfit(x[train], e[train], 2)
        a = np.polyval(coef, x)
        test = out_of_sample_test(e[val], a[val], np.flatnonzero(val), val)
        hits += test.p < 0.10
    assert hits / n <= 0.16


def _square_tested(options=None):
    """A pure x² on c0: every candidate tested, with the validation mask."""
    t, x, y = make_data(5, effects=[("quadratic", "c0", 0.4)])
    ad = ToyAdapter(t, x, y)
    blocks = split_blocks(len(t))
    train, val = blocks.mask("train"), blocks.mask("validation")
    fitted = ad.fit((), train)
    res = ad.residuals(fitted)
    cands = ad.candidates(fitted, res, train)
    return evaluate_candidates(cands, res, {c: 1.0 for c in res.channels}, train, val, options or EngineOptions()), val


def test_the_out_of_sample_test_counts_given_units_not_sub_blocks():
    """An open-loop error carries through its 2-s window, whatever its correlation time looks
    like: given the windows, the test has one degree of freedom per window less one, where the
    sub-blocks of a residual that looks white give many more."""
    rng = np.random.default_rng(5)
    T, n = 2000, 200
    window = np.arange(T) // n
    a = rng.normal(size=T)
    r = 0.2 * a + rng.normal(0, 0.3, T)
    mask, idx = np.ones(T, bool), np.arange(T)
    given = out_of_sample_test(r, a, idx, mask, window)
    assert given.df == T // n - 1
    assert out_of_sample_test(r, a, idx, mask).df > 3 * given.df
    assert given.sse_before == pytest.approx(float(r @ r))


def test_one_standard_error_rule_prefers_the_simpler_term():
    """A pure x² on c0: 'square' (1 parameter) and 'poly' (x², x³) fit equally well; the simpler
    wins."""
    tested, val = _square_tested()
    causes = {t.term.cause for t in tested if t.significant}
    assert {"square", "poly"} <= causes
    assert choose(tested, val).term.cause == "square"
    threads, _ = _square_tested(EngineOptions(jobs=2))  # fitted and tested in two threads
    assert [(t.term.cause, t.term.channel, t.test.t, t.significant) for t in threads] == [
        (t.term.cause, t.term.channel, t.test.t, t.significant) for t in tested
    ]


def test_a_wide_candidate_s_fit_takes_a_second_pass_with_the_same_standard_errors(monkeypatch):
    """A fit inflates its standard errors by the correlation time of its summed errors per sample:
    from per-sample sums held in one pass, or, past ONE_PASS_FLOATS, from a second pass over the
    rows (what a flexible model of a long log needs): the same numbers to rounding."""
    import diegocal.diagnose.selection as selection

    one, _ = _square_tested()
    monkeypatch.setattr(selection, "ONE_PASS_FLOATS", 0)
    two, _ = _square_tested()
    assert len(one) == len(two) > 1
    for a, b in zip(one, two, strict=True):
        assert (a.term.cause, a.term.channel) == (b.term.cause, b.term.channel)
        np.testing.assert_allclose([p.stderr for p in a.term.parameters], [p.stderr for p in b.term.parameters],
                                   rtol=1e-9)


def test_a_tested_candidate_keeps_its_errors_on_the_validation_samples_only():
    """Every tested candidate keeps what it removes per sample for the one-SE rule: on the validation
    samples only (a fifth of a long log, not all of it), with the same paired comparison."""
    from diegocal.diagnose.stats import paired_difference
    from diegocal.evaluate import sub_blocks

    rng = np.random.default_rng(7)
    T = 2000
    val = np.zeros(T, bool)
    val[300:700] = val[1200:1500] = True
    idx = np.flatnonzero(val)
    r, a, b = rng.normal(size=(3, idx.size))
    one, two = out_of_sample_test(r, a, idx, val), out_of_sample_test(r, b, idx, val)
    assert one.removed.shape == (val.sum(),)
    np.testing.assert_allclose(one.removed, r**2 - (r - a) ** 2, rtol=1e-12, atol=1e-12)
    assert one.sse_after == pytest.approx(np.sum((r - a) ** 2), rel=1e-12)
    cl = sub_blocks(val, 50)[idx]  # the paired difference written out over the whole log's labels
    d = np.bincount(cl, weights=(r - a) ** 2 - (r - b) ** 2)
    mean, se, n = paired_difference(two.removed, one.removed, val, 50)
    assert (mean, n) == (pytest.approx(d.mean(), rel=1e-12), d.size)
    assert se == pytest.approx(d.std(ddof=1) / np.sqrt(d.size), rel=1e-12)


class SpikyToy(ToyAdapter):
    """The toy with a detector that flags readings of c0 as a fault (``spikes``): the flagged
    readings are left out of the fit and of every score."""

    def __init__(self, t, x, y, flagged):
        super().__init__(t, x, y)
        self.flagged = flagged

    def faults(self, fitted, res):
        term = Term("spikes", "c0", ())
        return [Fault(term, {"c0": self.flagged}, exclude=True)]

    def fit(self, terms, train):
        spikes = any(t.cause == "spikes" for t in terms)
        fitted = super().fit([t for t in terms if t.cause != "spikes"], train & ~self.flagged if spikes else train)
        return replace(fitted, terms=tuple(terms))

    def terms(self, fitted):
        return super().terms(fitted) + tuple(t for t in fitted.terms if t.cause == "spikes")

    def score(self, fitted, mask, exclude=None):
        y = self.y.copy()
        for c, m in (exclude or {}).items():
            y[np.asarray(m, bool), CHANNELS.index(c)] = np.nan
        return score(y, self.predict(fitted), CHANNELS, mask=mask, unit="u")


@pytest.mark.parametrize("spiked", [True, False])
def test_a_fault_is_a_finding_only_when_writing_it_off_removes_error(spiked):
    """Readings flagged by a detector: spikes 100x the noise on them are a fault worth writing
    off; the same readings without spikes (a detector's false alarms) are no finding, however
    slightly leaving them out happens to lower the held-out error: a minor fault."""
    t, x, y = make_data(11)
    flagged = np.zeros(len(t), bool)
    flagged[np.random.default_rng(2).choice(len(t), 40, replace=False)] = True
    if spiked:
        y[flagged, 0] += 10.0
    d = run_unit(SpikyToy(t, x, y, flagged), split_blocks(len(t)), EngineOptions())
    faults = [f for f in d.findings if f.kind == "fault"]
    if spiked:
        assert [f.cause for f in faults] == ["spikes"] and faults[0].gain()["reduction"] > 0.2
    else:
        assert faults == []
    minor = [(f.cause, f.evidence["written_off"]) for f in d.minor_faults]
    assert minor == ([] if spiked else [("spikes", True)])  # said apart, written off: it lowered the error a little


def test_the_unplaced_span_of_a_time_region_is_the_gap_around_its_edge():
    time = np.arange(100) * 0.1
    train = np.ones(100, bool)
    train[40:60] = False
    assert unplaced_span(Term("slip", "c0", (), Region("time", 5.0, np.inf)), time, train).nonzero()[
        0
    ].tolist() == list(range(40, 60))
    assert unplaced_span(Term("slip", "c0", (), Region("time", 2.0, np.inf)), time, train) is None  # among training
    assert unplaced_span(Term("bump", "c0", (), Region("x.c0", 5.0, 6.0)), time, train) is None  # not in time


def test_candidates_that_fit_the_data_the_same_are_one_finding_to_it():
    """A joint's offset along the axis of the joint before it is that joint's offset: both fit
    the validation data the same (to rounding), and the finding names the other as
    indistinguishable; a candidate that fits a little worse, or acts on other channels, is not."""

    def tested(channel, sse_after, channels=("m1", "m2")):
        test = SimpleNamespace(sse_before=100.0, sse_after=sse_after)
        return SimpleNamespace(term=Term("link_offset", channel, ()), channels=channels, test=test)

    chosen = tested("hip_yaw", 60.0)
    others = [
        chosen,
        tested("knee", 60.3),  # 0.75 % of the 40 removed
        tested("ankle", 61.0),  # 2.5 %: the data prefer the chosen one
        tested("elbow", 60.0, ("m3",)),  # other channels
    ]
    assert indistinguishable(chosen, others) == ["knee"]


def test_a_candidate_on_overlapping_channels_that_removes_as_much_is_one_finding_to_the_data():
    """A joint's origin moved along the axis of the joint before it: the proximal joint's offset
    acts on one more marker (whose place takes it up) and removes as much of the validation error,
    to within the noise of a difference that drifts with the pose. It is listed as
    indistinguishable, judged on sub-blocks as long as that drift's correlation time (on the
    test's own short sub-blocks the drift looks significant); one that removes clearly less, or
    acts on other channels, is not."""
    rng = np.random.default_rng(11)
    T = 2400
    val = np.zeros(T, bool)
    val[300:900] = val[1500:2100] = True
    n = int(val.sum())
    base = 2.0 + rng.normal(0, 1.0, n)
    drift = 0.6 + 3.0 * np.sin(2 * np.pi * np.arange(n) / 400)  # a pose-driven difference, period 400 samples

    def tested(channel, removed, channels):
        test = SimpleNamespace(sse_before=1e4, sse_after=1e4 - removed.sum(), removed=removed, length=15)
        return SimpleNamespace(term=Term("link_offset", channel, ()), channels=channels, test=test, significant=True)

    chosen = tested("shoulder_yaw", base + drift, ("m1", "m2", "m3"))
    others = [
        chosen,
        tested("elbow", base.copy(), ("m1", "m2")),
        tested("wrist", base - 3.0, ("m2",)),  # removes clearly less
        tested("knee", base.copy(), ("m7",)),  # other channels
    ]
    assert indistinguishable(chosen, others, val) == ["elbow"]
    assert indistinguishable(chosen, others) == []  # without the validation rows: the same columns only
    from diegocal.diagnose.stats import paired_difference
    from diegocal.evaluate import sub_blocks

    cl = sub_blocks(val, 15)[val]  # the test's own sub-blocks: the drift looks like a difference
    d = np.bincount(cl, weights=drift)
    assert abs(d.mean()) > 2 * d.std(ddof=1) / np.sqrt(d.size)
    mean, se, k = paired_difference(chosen.test.removed, others[1].test.removed, val, 15)
    assert k < d.size and abs(mean) <= 2 * se


def test_a_term_is_weighed_against_the_flexible_model_on_its_own_channel():
    """A pot's curve moves the tracked joint, so its correction reaches the markers too, more there
    than on the pot. The flexible model is fitted on the pot only: the term must be weighed by what
    it explains there, not by its share over every channel it touches (diluted by a noisy marker,
    which made the offsim iCub's loaded-wiper pot a stand-in, left ``unexplained``)."""
    from diegocal.diagnose.stand_ins import outshone as _outshone
    from diegocal.diagnose.types import Candidate, Residuals
    from diegocal.terms import Parameter

    rng = np.random.default_rng(3)
    T = 4000
    x = np.sin(2 * np.pi * 0.07 * np.arange(T) * 0.01) + 0.1 * rng.normal(size=T).cumsum() / 30
    curve = 0.3 * x**2
    res = Residuals(
        {"pot": curve + rng.normal(0, 0.1, T), "marker": 3 * curve + rng.normal(0, 3.0, T)},
        {"pot": "V", "marker": "m"},
        {"time": np.arange(T) * 0.01, "p.pot": x},
        {"pot": ("p.pot",), "marker": ()},
    )
    blocks = split_blocks(T)
    train, val = blocks.mask("train"), blocks.mask("validation")
    term = Term("sensor_nonlinearity", "pot", (Parameter("c2"),))
    cand = Candidate(term, {"pot": x[:, None] ** 2, "marker": 3 * x[:, None] ** 2})
    weights = {"pot": 1.0, "marker": 1.0}
    options = EngineOptions()
    (t,) = evaluate_candidates([cand], res, weights, train, val, options)
    assert t.channel_gain is None  # it acts more on the marker than on its pot
    assert t.test.gain < 0.3 < 0.6 < t.own_gain  # diluted over both; most of the pot's error
    assert _outshone(t, res, weights, train, val, options, {}) is None


def _hose_like(seed: int = 4, T: int = 4000):
    """A joint whose residual is a hose's torque, linear in another joint's angle (context), with a
    candidate whose column hangs partly on that angle (a gain's: the joint's own torque), and a
    friction-like candidate of the joint's own velocity."""
    from diegocal.diagnose.types import Candidate, Residuals
    from diegocal.terms import Parameter

    rng = np.random.default_rng(seed)
    t = np.arange(T) * 0.01
    q1, q2 = np.sin(2 * np.pi * 0.31 * t), np.sin(2 * np.pi * 0.47 * t + 1.0)
    qd1 = np.gradient(q1, t)
    gain_column = q2 + 0.7 * q1  # its own angle's part and the other joint's
    variables = {"time": t, "q.j1": q1, "qd.j1": qd1, "q.j2": q2}

    def residuals(r):
        return Residuals({"j1": r + rng.normal(0, 0.05, T)}, {"j1": "N·m"}, variables, {"j1": ("q.j1", "qd.j1")},
                         {"j1": ("q.j2",)})

    gain = Candidate(Term("torque_gain", "j1", (Parameter("gain_error"),)), {"j1": gain_column[:, None]})
    shape = np.tanh(qd1 / 0.1)
    friction = Candidate(Term("stribeck_friction", "j1", (Parameter("amplitude"),)), {"j1": shape[:, None]})
    return residuals, gain_column, q2, shape, gain, friction


def test_a_term_that_leaves_most_of_its_channel_s_structure_to_the_flexible_model_stands_in():
    """A user trial's hose on a Kinova's joint 2 (a torque linear in q3) was named a torque gain
    there: the gain's column hangs on q3, so it removed 76 % of the joint's validation error, more
    than half of the flexible model's 92 %, and left the flexible model most of the rest. Such a
    term stands in; a true gain beside a friction's shape that another term of the round takes up
    is named."""
    from diegocal.diagnose.stand_ins import STAND_IN_SHARE, outshone

    residuals, _, q2, _, gain, friction = _hose_like()
    res = residuals(q2)
    blocks = split_blocks(len(q2))
    train, val = blocks.mask("train"), blocks.mask("validation")
    weights, options = {"j1": 1.0}, EngineOptions()
    tested = evaluate_candidates([gain, friction], res, weights, train, val, options)
    best = next(t for t in tested if t.term.cause == "torque_gain")
    flex = outshone(best, res, weights, train, val, options, {}, tested)
    assert flex is not None and best.gain >= STAND_IN_SHARE * flex.test.gain  # more than half, and yet
    # a true gain beside a friction's shape that no term of the round takes up stands in too ...
    residuals, column, _, shape, gain, friction = _hose_like()
    res = residuals(0.5 * column + 0.3 * shape)
    best, other = evaluate_candidates([gain, friction], res, weights, train, val, options)
    assert best.term.cause == "torque_gain" and not other.significant
    assert outshone(best, res, weights, train, val, options, {}, [best, other]) is not None
    # ... which the friction term of the round, significant, takes up: the gain is named
    other = replace(other, significant=True)
    assert outshone(best, res, weights, train, val, options, {}, [best, other]) is None

def test_a_term_that_removes_little_held_out_error_is_declined():
    """Significant on validation is not enough: a term must remove ``min_gain`` of the held-out mean
    squared error on its channel, as a fault must (a warming pot was named a backlash on its
    sibling pot with 0.6 % held out)."""
    from diegocal.diagnose.engine import _decline
    from diegocal.diagnose.types import Finding
    from diegocal.terms import Parameter

    rng = np.random.default_rng(1)
    y = rng.normal(size=(400, 1))
    term = Term("backlash", "dip", (Parameter("half_width", 0.004, "V", stderr=0.0005),))

    def finding(ratio):  # the held-out RMSE after = ratio × before
        before = score(y, np.zeros_like(y), ("dip",), unit="V")
        after = score(y, y * (1.0 - ratio), ("dip",), unit="V")
        return Finding(term, "term", before, after, {"channels": ["dip"]})

    assert "removes 3.2% of the held-out error (under 5%)" in _decline(finding(0.984), 0.05)  # 1.6 % RMSE
    assert _decline(finding(0.97), 0.05) == ""  # 3 % RMSE: 5.9 % of the mean squared error
    assert "rose" in _decline(finding(1.02), 0.05)


def test_a_declined_term_on_a_slide_says_its_bound_in_the_slides_unit():
    """A Stribeck scale at the end of its search on a Panda's finger (a prismatic joint) read
    "2 rad/s": the reason takes the term's own unit (m/s on a slide), not the registry's."""
    from diegocal.diagnose.engine import _decline
    from diegocal.diagnose.types import Finding
    from diegocal.terms import Parameter

    y = np.random.default_rng(2).normal(size=(400, 1))
    params = (Parameter("amplitude", -0.01, "N", stderr=0.001), Parameter("velocity_scale", 2.0, "m/s", stderr=0.1))
    term = Term("stribeck_friction", "panda_finger_joint1", params)
    before = score(y, np.zeros_like(y), ("panda_finger_joint1",), unit="N")
    after = score(y, y * 0.5, ("panda_finger_joint1",), unit="N")
    why = _decline(Finding(term, "term", before, after, {"channels": ["panda_finger_joint1"]}), 0.05)
    assert "velocity_scale ends at the end of its search (2 m/s)" in why


def test_a_term_weaker_than_a_declined_one_on_its_channel_stands_in_for_it():
    """A pressure offset that the held-out rows did not confirm, then a supply sag that a constant
    offset partly mimics (offsim, seed 3783616092: 74 % of the validation error against 48 %): the
    sag is no cause the data single out. A declined term that removes less, or on other channels,
    does not block it."""
    from diegocal.diagnose.stand_ins import declined_rival

    def tested(cause, channel, sse_after, channels=None):
        test = SimpleNamespace(sse_before=100.0, sse_after=sse_after)
        term = Term(cause, channel, ())
        return SimpleNamespace(term=term, channels=channels or (channel,), test=test, strongest=None)

    droop = tested("supply_droop", "c", 52.0)
    offset, leak = tested("pressure_offset", "c", 26.0), tested("chamber_leak", "c", 70.0)
    elsewhere = tested("pressure_offset", "d", 10.0)
    # a term on more channels than the sag's (a pot term on its markers), or judged elsewhere
    wider = tested("backlash", "c", 20.0, ("c", "m"))
    wider.test.sse_before = 300.0
    declined = {("pressure_offset", "c"): "the held-out error rose", ("pressure_offset", "d"): "rose"}
    assert declined_rival(droop, [droop, offset, leak, elsewhere], declined) is offset
    assert declined_rival(droop, [droop, leak, elsewhere], {**declined, ("chamber_leak", "c"): "rose"}) is None
    assert declined_rival(offset, [droop, offset], {("supply_droop", "c"): "rose"}) is None
    assert declined_rival(droop, [droop, wider], {("backlash", "c"): "rose"}) is None


def test_a_term_judged_on_several_channels_loses_to_its_channel_s_rival_when_both_are_refitted():
    """A gain judged on every joint is credited with what the refit of the shared parameters gains on
    the others, an offset only with its own joint's: the refits judge both on the same channels, and
    the one that leaves less of their weighted validation error wins (a Z1 shoulder's offset had
    been named a gain). A rival with more parameters, on another channel, or judged on the same
    channels is not refitted, nor a cause tested on several channels at once; a best term on one
    channel, or one that names none of its channels (a payload on a link), has no such rival."""
    from diegocal.diagnose.stand_ins import refit_rival

    left = {"gain": [2.0, 1.0], "offset": [1.5, 1.0], "spring": [0.1, 0.1], "lag": [0.1, 0.1]}  # RMSE on c, d

    class Refits:
        def fit(self, terms, train):
            return terms[-1].cause

        def score(self, fitted, mask, exclude):
            return SimpleNamespace(channels=["c", "d"], rmse=np.array(left[fitted]), n_samples=np.array([10, 10]))

    def tested(cause, channels, n_params=1, significant=True, own="c"):
        test = SimpleNamespace(sse_before=100.0, sse_after=50.0)
        return SimpleNamespace(term=Term(cause, own, ()), channels=channels, test=test, strongest=None,
                               significant=significant, n_params=n_params, candidate=SimpleNamespace(members=()))

    gain, offset = tested("gain", ("c", "d")), tested("offset", ("c",))
    spring, lag = tested("spring", ("c",), n_params=2), tested("lag", ("c", "d"))
    elsewhere = tested("lag", ("d",), own="d")
    common = tested("spring", ("c",))  # one cause tested on several channels at once: no term to refit
    common.candidate.members = (spring,)
    judge = partial(refit_rival, Refits(), (), (None, None), {"c": 1.0, "d": 1.0}, {})
    rival, why = judge(gain, [gain, offset, spring, lag, elsewhere, common])
    assert rival is offset and "offset:c leaves less of the validation error of c, d" in why
    assert "(65% of what gain leaves)" in why  # (1.5² + 1) / (2² + 1) of the weighted squares
    left["offset"] = [2.5, 1.0]
    assert judge(gain, [gain, offset]) is None
    assert judge(gain, [gain, tested("offset", ("c",), significant=False)]) is None
    assert judge(offset, [offset, gain]) is None  # judged on one channel: nothing to credit it with
    payload = tested("payload", ("c", "d"), own="link")
    assert judge(payload, [payload, offset]) is None


def test_a_term_that_a_model_of_another_shape_beats_on_the_adapter_s_score_stands_in_for_it():
    """An adapter's ``shape_rival`` (a chamber's pressure read through a filter) is asked about the
    term the engine would name; when it returns a rival, the channel is ``unexplained`` with the
    rival's evidence and the term named as its stand-in; the other channel is named as before."""
    from diegocal.diagnose.types import Tested

    t, x, y = make_data(3, effects=[("bump", "c0", 0.5), ("quadratic", "c1", 0.4)])
    asked = []

    class Rivalled(ToyAdapter):
        def shape_rival(self, fitted, train, val, options, exclude, term):
            asked.append(term.channel)
            if term.channel != "c0":
                return None
            rows = np.flatnonzero(val)
            r = self.y[rows, 0] - fitted.a[0] * self.x[rows, 0] - fitted.b[0]
            test = out_of_sample_test(r, 0.9 * r, rows, val)
            rival = Tested(Term("unexplained", "c0", ()), ("c0",), test, 3.0, True, 1, None)
            return rival, {"model": "a toy rival", "open_loop_validation_gain": 0.5}

    d = run_unit(Rivalled(t, x, y), split_blocks(len(t)), EngineOptions())
    assert {"c0", "c1"} <= set(asked)
    on = {f.channel: f for f in d.findings}
    assert on["c0"].kind == "unexplained" and on["c0"].evidence["rival"]["model"] == "a toy rival"
    assert on["c0"].evidence["stand_in"]["term"].startswith("bump")
    assert on["c0"].evidence["validation_gain"] == pytest.approx(0.99)  # the rival's test's
    assert on["c0"].evidence["rival"]["open_loop_validation_gain"] == 0.5
    assert on["c1"].cause in ("square", "poly")


def test_a_common_cause_leaves_out_a_channel_where_a_declined_term_explains_more(monkeypatch):
    """The same cause added on other channels in one round (friction on every joint) is held to
    the declined-rival test of each channel, as the round's best is."""
    from diegocal.diagnose import stand_ins

    monkeypatch.setattr(stand_ins, "outshone", lambda *args: None)  # no flexible model beats any of them

    @dataclass(frozen=True)
    class Tested:  # what the stand-in tests read of a selection.Tested
        term: Term
        channels: tuple
        test: SimpleNamespace
        strongest: None = None
        significant: bool = True
        candidate: object = None

    def tested(cause, channel, sse_after):
        return Tested(Term(cause, channel, ()), (channel,), SimpleNamespace(sse_before=100.0, sse_after=sse_after))

    best, other = tested("viscous_friction", "j1", 40.0), tested("viscous_friction", "j2", 60.0)
    lag = tested("torque_lag", "j2", 30.0)
    args = (None, None, None, None, EngineOptions(), {})
    assert stand_ins.same_cause_beside(best, [best, other, lag], {}, *args) == [other]
    stood = {}
    declined = {("torque_lag", "j2"): "rose held out"}
    assert stand_ins.same_cause_beside(best, [best, other, lag], declined, *args, stood) == []
    assert list(stood) == ["j2"] and stood["j2"][2] == {"declined": {"term": "torque_lag:j2", "why": "rose held out"}}


def test_a_progress_line_names_the_unit_in_brackets_after_the_channel():
    """A robot's joint reads "joint_6 (staubli_tx40)"; a chamber, its own unit, is named once."""
    from diegocal.diagnose.engine import _where

    assert _where("joint_6", " staubli_tx40") == "joint_6 (staubli_tx40)"
    assert _where("elbow.flex", " elbow.flex") == "elbow.flex"
    assert _where("c0", "") == "c0"


def test_a_term_whose_parameter_ends_at_the_end_of_its_search_is_declined():
    """TIAGo's torso lift (first half) gave torque_lag 0.49995 s, the lag's search ending at 0.5 s:
    the data want more than a sensor's lag, and the term would stand in for it. It is declined,
    with why; a lag inside the search is judged as before."""
    from diegocal.diagnose.engine import _decline
    from diegocal.diagnose.types import Finding
    from diegocal.terms import make_term

    at_end = Finding(make_term("torque_lag", "torso", {"lag": 0.49995}), "term", None, None)
    assert _decline(at_end, 0.05) == "its lag ends at the end of its search (0.5 s): the data want more"
    inside = Finding(make_term("torque_lag", "torso", {"lag": 0.2}, stderr={"lag": 0.5}), "term", None, None)
    assert "end of its search" not in _decline(inside, 0.05)


def test_a_term_that_wants_a_negative_friction_or_dead_band_is_declined():
    """A user trial's cogging (0.15 sin(12 q)) was named coupled_friction with Coulomb -0.048 ±
    0.003 N·m, and an armature -0.033 kg·m²: quantities that cannot be negative. Such a term stands
    in for something else and is declined, with why; a negative value within two standard errors of
    0, and a signed cause (a spring), are judged as before."""
    from diegocal.diagnose.engine import _decline
    from diegocal.diagnose.types import Finding
    from diegocal.terms import make_term

    def decline(cause, values, stderr, extra=None):
        return _decline(Finding(make_term(cause, "j", values, extra=extra, stderr=stderr), "term", None, None), 0.05)

    why = decline("coupled_friction", {"coulomb": -0.0484, "viscous": 0.01}, {"coulomb": 0.0027, "viscous": 0.002},
                  {"partner": "k", "ratio": -0.5})
    assert why.startswith("its coulomb is negative (-0.0484 ± 0.0027 N·m), which coupled_friction cannot be")
    assert decline("armature", {"inertia": -0.0327}, {"inertia": 0.0016}).startswith("its inertia is negative")
    assert "negative" not in decline("armature", {"inertia": -0.0005}, {"inertia": 0.0004})
    # a backlash's reading leads the link where the pot reads the motor's side of the play (the
    # independent generator's UR5): a negative half-width is a backlash too
    assert "negative" not in decline("backlash", {"half_width": -0.0105}, {"half_width": 0.0004})
    # a payload's mass the torques do not identify (NaN standard error) means nothing, whatever its sign
    assert "negative" not in decline("payload", {"mass": -0.02, "mc_x": 0.1}, {"mass": np.nan, "mc_x": 0.001})
    assert "negative" not in decline("spring", {"stiffness": -2.0}, {"stiffness": 0.1})
    # a region's friction is beyond the joint's own: less friction there is a negative level (a user
    # trial's position friction, found on the complement of its true region, came out -0.25 N·m)
    region = Region("q.j", -2.88, -1.5)
    assert "negative" not in _decline(Finding(make_term("position_friction", "j", {"coulomb": -0.25, "viscous": 0.1},
                                                        region=region, stderr={"coulomb": 0.004, "viscous": 0.01}),
                                              "term", None, None), 0.05)
    assert "negative" not in decline("stribeck_friction", {"amplitude": -1.0, "velocity_scale": 0.02},
                                     {"amplitude": 0.1, "velocity_scale": 0.001})


def test_another_cause_that_fits_the_same_is_named_beside_the_finding():
    """A user trial's torque offset on a joint that never nears 0 rad was named a spring, the offset
    fitting the validation data the same (0.3776 against 0.3776): the finding names the offset as
    a cause the data cannot tell from it. A rival that removes clearly less, or acts elsewhere, is not."""
    from diegocal.diagnose.engine import rival_causes

    def tested(cause, channel, sse_after, significant=True):
        test = SimpleNamespace(sse_before=100.0, sse_after=sse_after)
        return SimpleNamespace(term=Term(cause, channel, ()), channels=(channel,), test=test,
                               significant=significant)

    spring = tested("spring", "joint2", 62.24)
    offset, lag = tested("torque_offset", "joint2", 62.30), tested("torque_lag", "joint2", 70.0)
    elsewhere, weak = tested("torque_offset", "joint3", 62.24), tested("armature", "joint2", 62.24, False)
    assert rival_causes(spring, [spring, offset, lag, elsewhere, weak]) == ["torque_offset:joint2"]


def test_a_cause_on_more_channels_that_removes_as_much_within_the_noise_is_named_beside_the_finding():
    """User trials: a torque offset named a spring that removed 1.1 % more of the validation error
    (outside the 1 % twin share), and a spring near a Kinova's upright pose named a payload on the
    link beyond, which acts on two joints where the spring acts on one. Either removes the same
    validation error to within the noise, paired over sub-blocks: the finding names the other. A
    rival that removes clearly less is not named."""
    from diegocal.diagnose.selection import rival_causes

    rng = np.random.default_rng(4)
    val = np.zeros(3000, bool)
    val[1000:2000] = True
    noise = rng.normal(0.0, 1.0, 1000)

    def tested(cause, channels, removed):
        test = SimpleNamespace(sse_before=1000.0, sse_after=1000.0 - removed.sum(), removed=removed, length=20)
        return SimpleNamespace(term=Term(cause, "+".join(channels), ()), channels=channels, test=test,
                               significant=True)

    payload = tested("payload", ("joint1", "joint2"), 0.60 + noise)
    spring = tested("spring", ("joint2",), 0.59 + noise + rng.normal(0.0, 0.3, 1000))
    lag = tested("torque_lag", ("joint2",), 0.30 + noise + rng.normal(0.0, 0.3, 1000))
    assert rival_causes(payload, [payload, spring, lag]) == []  # other channels: the 1 % share never compared them
    assert rival_causes(payload, [payload, spring, lag], val) == ["spring:joint2"]


def test_a_link_offset_not_fixed_alone_is_judged_by_its_held_out_gain():
    """A user trial's Z1 joint 4: dx and dz each not fixed by the data (infinite SE), a combination of
    them fixed and worth 10 % of the markers' held-out error; dy 0 ± 8e-5. It had been declined as
    "every coefficient within 2 standard errors of 0" on dy alone."""
    from diegocal.diagnose.engine import _decline
    from diegocal.diagnose.types import Finding
    from diegocal.terms import make_term

    values, se = {"dx": 0.0079, "dy": 1e-5, "dz": 0.0021}, {"dx": np.inf, "dy": 7.7e-5, "dz": np.inf}
    assert "do not determine" not in _decline(Finding(make_term("link_offset", "joint4", values, stderr=se),
                                                      "term", None, None), 0.05)
    fixed = {"dx": 0.002, "dy": 1e-5, "dz": 0.0}, {"dx": 0.002, "dy": 7.7e-5, "dz": 0.001}
    assert "do not determine" in _decline(Finding(make_term("link_offset", "joint4", fixed[0], stderr=fixed[1]),
                                                  "term", None, None), 0.05)


def test_a_link_offset_starts_its_refinement_at_zero_where_its_linear_estimate_is_far_off():
    """The same trial's candidate came with dx -1.6 km and dz 6.1 km from its linear test, along the
    direction the data barely fix; its refinement stayed there (held-out error × 39,000)."""
    from diegocal.diagnose.kinematics_refine import plausible_start
    from diegocal.terms import make_term

    far = make_term("link_offset", "joint4", {"dx": -1604.3, "dy": -1e-5, "dz": 6135.9})
    assert plausible_start(far).values.tolist() == [0.0, -1e-5, 0.0]
    near = make_term("link_offset", "joint4", {"dx": 0.008, "dy": 0.0, "dz": -0.007})
    assert plausible_start(near) is near


def test_an_unexplained_structure_linear_in_its_variable_spans_its_range():
    """A user trial: a hose's torque linear in the next joint's angle was given the region where the
    residual is largest (q.elbow 0.64-1.58 of -1.32-1.58): a structure at both ends spans the range,
    a bump keeps its bins."""
    from diegocal.diagnose.show import unexplained_region
    from diegocal.terms import Region

    edges = np.array([-1.32, -1.06, -0.79, -0.56, -0.2, -0.06, 0.05, 0.26, 0.49, 0.64, 1.58])
    centre = 0.5 * (edges[:-1] + edges[1:])

    def tested(means):
        term = SimpleNamespace(extra={"edges": list(edges)}, values=np.asarray(means, float),
                               region=Region("q.elbow", edges[0], edges[-1]))
        return SimpleNamespace(term=term)

    hose = unexplained_region(tested([-1.26, -0.43, 0.15, 0.16, -0.04, -0.27, -0.27, -0.13, 0.12, 1.82]))
    assert (hose.low, hose.high) == (edges[0], edges[-1])  # the trial's fitted bins
    bump = unexplained_region(tested(np.exp(-(((centre - 0.3) / 0.2) ** 2))))
    assert edges[0] < bump.low < 0.3 < bump.high < edges[-1]


def test_friction_near_zero_velocity_is_shown_against_the_velocity():
    """A report review: TIAGo's Stribeck findings were drawn against the joint's angle, where the
    residual times the direction of motion follows zero; their shape is a function of the velocity."""
    from diegocal.diagnose.evidence import curves, evidence_variable
    from diegocal.diagnose.types import Residuals
    from diegocal.terms import make_term

    rng = np.random.default_rng(3)
    qd = rng.normal(0.0, 0.3, 2000)
    q = np.cumsum(qd) * 0.01
    r = -2.0 * np.sign(qd) * np.exp(-np.abs(qd) / 0.02) + 0.05 * rng.standard_normal(2000)
    res = Residuals({"j": r}, {"j": "N·m"}, {"q.j": q, "qd.j": qd}, {"j": ("q.j", "qd.j")})
    assert evidence_variable(make_term("stribeck_friction", "j"), res) == "qd.j"
    assert evidence_variable(make_term("viscous_friction", "j"), res) == "q.j"
    train = np.arange(2000) % 3 == 0
    out = curves(res, None, "j", "qd.j", ~train, 100, train, 10, None, signed_by="qd")
    edges = np.asarray(out["before"]["edges"])
    assert 0.0 in edges and np.sum(np.abs(edges) < 0.02) >= 3  # fine bins on each side of rest
