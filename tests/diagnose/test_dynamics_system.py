"""The dynamics diagnosis's factored training system and chunked projection (issue #33) against
the direct routes they replace: the weighted least squares on the full columns, ``pinv(X)`` on the
whole training matrix, the prediction on every sample at once."""

from __future__ import annotations

import numpy as np
import pytest

import diegocal.diagnose.dynamics_system as system_module
import diegocal.sgp.model as sgp_model
from diegocal import progress
from diegocal.diagnose.dynamics import adapters
from diegocal.diagnose.dynamics_system import TrainingSystem, project
from diegocal.diagnose.selection import channel_weights, evaluate_candidates
from diegocal.diagnose.types import EngineOptions
from diegocal.progress import Eta
from diegocal.robot import load_robot
from diegocal.robot.model import BUNDLED_ROBOTS
from diegocal.sgp.terms import SPRING_RESTS, term_columns
from diegocal.sim.dynamics import DynamicsOptions, simulate_dynamics
from diegocal.terms import Region, make_term


@pytest.fixture(scope="module")
def adapter():
    robot = load_robot(BUNDLED_ROBOTS / "arm3")
    opts = DynamicsOptions(duration=8.0, noise=0.01)
    log = simulate_dynamics(robot, opts, np.random.default_rng(3))
    (ad,) = adapters(log, robot, None)
    ad.tau = ad.tau.copy()  # the log's samples are read-only: the test's own copy to write into
    ad.tau[5, 1] = np.nan  # a missing torque: its row is left out of every fit
    return ad


@pytest.fixture(scope="module")
def train(adapter):
    mask = np.zeros(len(adapter.time), bool)
    mask[: int(0.6 * mask.size)] = True
    return mask


@pytest.fixture(autouse=True)
def small_chunks(monkeypatch):
    """Chunks of a few samples, so that every chunked route really joins many chunks."""
    monkeypatch.setattr(system_module, "CHUNK", 97)
    monkeypatch.setattr(system_module, "SAMPLES", 211)
    monkeypatch.setattr(sgp_model, "PREDICT_SAMPLES", 211)  # the model's own chunked prediction


def friction_in(adapter, joint: int, low: float, high: float):
    name = adapter.joints[joint]
    return make_term("position_friction", name, region=Region(f"q.{name}", low, high))


def direct(adapter, terms, train, sigma):
    """The weighted least squares on the full columns [F C] (the route the system replaces)."""
    C = term_columns(terms, adapter.robot, adapter.q, adapter.qd, adapter.qdd)[:, adapter.rows]
    A = np.concatenate([adapter.F, C], axis=2)
    w, _ = adapter._solve(A, train, sigma)
    e = (adapter.tau[train] - (A @ w + adapter.tau0)[train]) / sigma
    return w, float(np.nansum(e * e))


@pytest.mark.parametrize("sigma", [(1.0, 1.0, 1.0), (0.02, 0.5, 3.0)])
def test_system_equals_direct_least_squares(adapter, train, sigma):
    sigma = np.array(sigma)
    q1 = adapter.q[train, adapter.rows[1]]
    terms = (friction_in(adapter, 1, *np.quantile(q1, [0.3, 0.7])),)
    w, cost, per_joint = TrainingSystem(adapter, train).weighted_fit(terms, sigma)
    w0, cost0 = direct(adapter, terms, train, sigma)
    np.testing.assert_allclose(w, w0, rtol=1e-7, atol=1e-9 * np.abs(w0).max())
    assert cost == pytest.approx(cost0, rel=1e-9)
    assert np.sum(per_joint / sigma**2) == pytest.approx(cost0, rel=1e-9)


def test_system_without_terms(adapter, train):
    sigma = np.array([0.1, 0.2, 0.3])
    w, cost, _ = TrainingSystem(adapter, train).weighted_fit((), sigma)
    w0, cost0 = direct(adapter, (), train, sigma)
    np.testing.assert_allclose(w, w0, rtol=1e-7, atol=1e-9 * np.abs(w0).max())
    assert cost == pytest.approx(cost0, rel=1e-9)


def test_system_declines_a_column_in_the_span(adapter, train):
    """Viscous friction is already in the baseline: its column is in the span, the system says
    so (None) and the caller solves directly."""
    terms = (make_term("viscous_friction", adapter.joints[0]),)
    assert TrainingSystem(adapter, train).weighted_fit(terms, np.ones(3)) is None


def test_projection_equals_pinv(adapter, train):
    fitted = adapter.fit((), train)
    T = len(adapter.time)
    rng = np.random.default_rng(0)
    A = fitted.model.features(adapter.q, adapter.qd, adapter.qdd, adapter.time)
    B = {0: rng.standard_normal((T, 3)), 1: 2.0 * A[:, 1, :1], 2: rng.standard_normal((T, 2))}
    B[0] = np.hstack([B[0], 2.0 * A[:, 0, :1]])
    B[2] = np.hstack([B[2], 2.0 * A[:, 2, :1]])
    # the last candidate is twice a model column on every joint: in the span (the near-span route)
    slots = [
        {0: slice(0, 2)},
        {0: slice(2, 3), 2: slice(0, 1)},
        {2: slice(1, 2)},
        {r: slice(w, w + 1) for r, w in ((0, 3), (1, 0), (2, 2))},
    ]
    original = {r: b.copy() for r, b in B.items()}
    width = {r: b.shape[1] for r, b in B.items()}
    fill = lambda rows, keep: {r: b[rows] for r, b in original.items()}  # noqa: E731
    B, frac, _ = project(adapter, fitted, train, width, slots, fill)
    # the direct route: c − X pinv(X) c, X the model's weighted training columns
    wt = 1.0 / fitted.sigma
    Xt = (A[train] * wt[None, :, None]).reshape(-1, A.shape[2])
    pinv = np.linalg.pinv(Xt)
    for slot, f in zip(slots, frac, strict=True):
        kc = next(iter(slot.values())).stop - next(iter(slot.values())).start
        c = np.zeros((train.sum(), 3, kc))
        for r, sl in slot.items():
            c[:, r] = original[r][train, sl] * wt[r]
        beta = pinv @ c.reshape(-1, kc)
        left = c.reshape(-1, kc) - Xt @ beta
        assert f == pytest.approx(np.sqrt(np.sum(left**2) / np.sum(c**2)), abs=1e-9)
        for r, sl in slot.items():
            expected = original[r][:, sl] - A[:, r] @ beta
            assert B[r].dtype == np.float32  # rounded once, from float64
            scale = np.abs(original[r][:, sl]).max()  # an in-span column projects to rounding
            np.testing.assert_allclose(B[r][:, sl], expected, rtol=1e-6, atol=1e-6 * scale)
    assert frac[3] < 1e-9 and min(frac[:3]) > 0.5


def test_chunked_prediction_equals_whole(adapter, train):
    fitted = adapter.fit((), train)
    whole = fitted.model.predict_arrays(adapter.q, adapter.qd, adapter.qdd, adapter.time, variance=False).tau
    np.testing.assert_allclose(fitted.pred, whole, rtol=1e-12, atol=1e-12)


def test_projection_says_how_far_its_passes_are(adapter, train, monkeypatch):
    monkeypatch.setattr(progress, "Eta", lambda total: Eta(total, every=0.0))  # every chunk
    fitted = adapter.fit((), train)
    T = len(adapter.time)
    cols = np.random.default_rng(1).standard_normal((T, 2))
    said = []
    project(adapter, fitted, train, {0: 2}, [{0: slice(0, 2)}], lambda rows, keep: {0: cols[rows]}, said.append)
    chunks = -(-int(train.sum()) // 211) + -(-T // 211)  # the training pass, then every sample
    assert len(said) == chunks
    assert said[-1].startswith(f"candidate columns projected, chunks of 211 samples: {chunks}/{chunks}")
    assert "left" in said[0]


@pytest.mark.parametrize("offsets", [False, True])
def test_each_family_keeps_the_variant_the_selection_tests(adapter, train, offsets):
    """With the engine's weights set, the adapter holds each family's best variant, ranked from
    the projection's sums (and any within a tie of it), with the same projected columns: the
    selection then keeps the very variant it keeps when it fits all of them. With a torque offset
    on every joint a joint's springs (their rest angles differ by a constant torque) tie exactly:
    all are held, and the selection's first-of-equals decides as before."""
    terms = tuple(make_term("torque_offset", j) for j in adapter.joints) if offsets else ()
    fitted = adapter.fit(terms, train)
    res = adapter.residuals(fitted)
    weights = channel_weights(res, train)
    validation = ~train
    everything = adapter.candidates(fitted, res, train)
    tested = evaluate_candidates(everything, res, weights, train, validation, EngineOptions())
    best = {t.candidate.family: t for t in tested}
    try:
        adapter.selection_weights = weights
        held = adapter.candidates(fitted, res, train)
    finally:
        adapter.selection_weights = None
    assert {c.family for c in held} == {c.family for c in everything}
    assert len(held) < len(everything) / 2  # lags, scales, regions, ratios: about one of each kept
    again = {t.candidate.family: t for t in evaluate_candidates(held, res, weights, train, validation, EngineOptions())}

    def variant(term):  # a variant's shape (a spring's rest angle, a velocity scale) is a parameter
        shape = [(p.name, p.value) for p in term.parameters if p not in term.linear]
        return term.cause, term.channel, term.region, sorted(term.extra.items()), shape

    for family, t in best.items():
        if not family:  # a family of its own: held whatever its fit
            continue
        assert variant(again[family].term) == variant(t.term)
        assert again[family].test.t == pytest.approx(t.test.t, rel=1e-9)
        for joint, cols in again[family].candidate.columns.items():
            whole = t.candidate.columns[joint]
            np.testing.assert_allclose(cols, whole, rtol=1e-6, atol=1e-6 * np.abs(whole).max())
    springs = [c for c in held if c.term.cause == "spring"]
    if offsets:  # every joint's springs (at its zero, its mean and SPRING_RESTS of its range) tie
        assert len(springs) == (2 + len(SPRING_RESTS)) * len(adapter.joints)
