"""A rival shape for a chamber's named term (issue #31: a wrong name is worse than ``unexplained``):
a pressure sensor that reads through a first-order filter, τ ẏ = p - y, with a time constant of
tens of milliseconds (a sensor at the end of a thin tube, or one whose electronics filter it).

No cause of the vocabulary has that shape (``sensor_lag`` is a tick at most). On the independent
thin-plate generator (``experiments/pneumatic_oov.py``) a supply sag (the filling looks slower)
or a valve delay (the answer to a command step looks later) stands in for it. Judged on one-step
residuals the rival cannot be told from a true sag: for τ ≫ h its column is about an AR(1)
predictor of the residual, whose coefficient fits a slow sensor and a true sag alike. Judged as
diagnose scores a chamber, by the open-loop pressure with resets every 2 s, it can
(``experiments/pneumatic_slow_sensor.py``, docs/results.md): on slow sensors the filter removes
far more of the open-loop error than any term, on true sags and delays it removes none.

The rival model: the chamber model fitted on the filter-inverted pressure y + τ ẏ (ẏ a central
difference), its open-loop pressure passed through the filter from the reading at each reset
(the reading's exact answer to a ramp between samples), τ from :data:`FILTER_TAUS_S`, the one
with the least open-loop error on the training blocks. It beats the round's best term when it is
significant on the validation blocks' open-loop error (the engine's cluster-robust test, the
correction being its change of the open-loop prediction) and leaves less of that error than the
model with the term does: the chamber is then ``unexplained`` and the term its stand-in
(:func:`~diegocal.diagnose.engine.run_unit`).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from diegocal.diagnose.stats import critical_t, out_of_sample_test
from diegocal.diagnose.types import EngineOptions, Tested
from diegocal.pneumatic.predict import predict_with_resets, reset_starts
from diegocal.sgp.terms import lag_filter
from diegocal.terms import Term

#: Time constants of the filtered-sensor rival, s: above the tick lag the baseline fits (10 ms),
#: up to about a tenth of a second (the grid's steps are about a factor 1.45).
FILTER_TAUS_S = (0.02, 0.03, 0.045, 0.065, 0.09)


def through_filter(p: np.ndarray, y: np.ndarray, starts: np.ndarray, time: np.ndarray, tau: float) -> np.ndarray:
    """The reading of a first-order filter (time constant ``tau``) of the pressure ``p`` (T,),
    piecewise linear between samples, started at the measured ``y`` at each reset ``starts``: the
    filter started at rest (:func:`~diegocal.sgp.terms.lag_filter`) plus the decay of the reading's
    gap to the pressure at the reset."""
    out = np.empty_like(p)
    edges = np.append(np.union1d([0], starts), p.size)
    for a, b in zip(edges[:-1], edges[1:], strict=True):
        decay = np.exp(-(time[a:b] - time[a]) / tau)
        out[a:b] = lag_filter(p[a:b], time[a:b], tau) + (y[a] - p[a]) * decay
    return out


def filtered_readings(adapter, terms, train, start_from) -> tuple[float, np.ndarray]:
    """(τ, the open-loop reading (T,)) of the filtered-sensor model of ``adapter``'s chamber with
    ``terms``: the τ of :data:`FILTER_TAUS_S` whose reading is nearest the measured one on the
    ``train`` samples (module docstring)."""
    data = adapter.data
    y = data.p.astype(float)
    starts = reset_starts(data)
    best = (np.inf, FILTER_TAUS_S[0], None)
    for tau in FILTER_TAUS_S:
        inverted = replace(data, p=y + tau * np.gradient(y, data.time))
        fit = type(adapter)(inverted, adapter.volume_sensor, adapter.options).fit(terms, train, start_from)
        reading = through_filter(predict_with_resets(fit.params, inverted), y, starts, data.time, tau)
        sse = float(np.nansum((reading - y)[np.asarray(train, bool)] ** 2))
        if sse < best[0]:
            best = (sse, tau, reading)
    return best[1], best[2]


def open_loop_test(y, now, other, rows: np.ndarray):
    """The engine's out-of-sample test (:func:`~diegocal.diagnose.stats.out_of_sample_test`) of the
    open-loop prediction ``other`` against ``now`` on the samples ``rows`` (T,) bool: the residual
    y - now, the correction other - now."""
    ok = rows & np.isfinite(y) & np.isfinite(now) & np.isfinite(other)
    idx = np.flatnonzero(ok)
    return out_of_sample_test((y - now)[idx], (other - now)[idx], idx, ok)


def filter_rival(adapter, fitted, train, val, options: EngineOptions, exclude, term: Term):
    """(the filtered-sensor rival as a tested candidate, its evidence) when it beats ``term`` on
    the validation blocks' open-loop error (module docstring), else None. ``fitted``: the model
    the round's candidates were tested against; ``exclude``: readings the selection leaves out."""
    name, data = adapter.unit_name, adapter.data
    y = data.p.astype(float).copy()
    if exclude and name in exclude:
        y[np.asarray(exclude[name], bool)] = np.nan
    terms = adapter.terms(fitted)
    now = predict_with_resets(fitted.params, data)
    named = predict_with_resets(adapter.fit(terms + (term,), np.asarray(train, bool)).params, data)
    tau, reading = filtered_readings(adapter, terms, train, fitted)
    val = np.asarray(val, bool)
    rival, with_term = open_loop_test(y, now, reading, val), open_loop_test(y, now, named, val)
    threshold = critical_t(options.alpha, options.n_units, rival.df)
    significant = bool(rival.t > threshold and rival.gain >= options.min_gain)
    if not (significant and rival.sse_after < with_term.sse_after):
        return None
    model = f"the pressure read through a first-order filter (τ {tau * 1e3:.0f} ms)"
    tested = Tested(Term("unexplained", name, ()), (name,), rival, threshold, significant, 1, None)
    evidence = {
        "model": model,
        "tau_s": tau,
        "open_loop_validation_gain": float(rival.gain),
        "term_open_loop_validation_gain": float(with_term.gain),
    }
    return tested, evidence
