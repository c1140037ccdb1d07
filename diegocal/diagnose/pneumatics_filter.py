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

The rival model: the chamber model of eq. (4.10) fitted on the filter-inverted pressure y + τ ẏ
(ẏ a central difference), its open-loop pressure (resets every 2 s, thesis Fig. 4.12) passed
through the filter from the reading at each reset (the reading's exact answer to a ramp between
evenly spaced samples), τ from :data:`FILTER_TAUS_S`, the one with the least open-loop error on
the training blocks. It beats the round's best term when it is significant on the validation
blocks' open-loop error (the engine's cluster-robust test with the open-loop windows as the
units, the correction being its change of the open-loop prediction; the gain a flexible model's
``unexplained`` needs) and leaves less of that error than the model with the term does, on the
same samples: the chamber is then ``unexplained`` and the term its stand-in
(:func:`~diegocal.diagnose.engine.run_unit`). The finding's ``validation_gain`` and ``t`` are
then the open-loop test's.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from diegocal.diagnose.stats import critical_t, out_of_sample_test
from diegocal.diagnose.types import EngineOptions, Tested
from diegocal.errors import FitError
from diegocal.pneumatic.predict import predict_with_resets, reset_starts
from diegocal.sgp.terms import lag_filter
from diegocal.terms import Term

#: Time constants of the filtered-sensor rival, s: from one and a half ticks (the baseline fits a
#: lag of up to a tick) to about a tenth of a second, in steps of a factor 1.3-1.5.
FILTER_TAUS_S = (0.015, 0.02, 0.03, 0.045, 0.065, 0.09)


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


def filtered_readings(adapter, terms, train, start_from) -> tuple[float, np.ndarray] | None:
    """(τ, the open-loop reading (T,)) of the filtered-sensor model of ``adapter``'s chamber with
    ``terms``: the τ of :data:`FILTER_TAUS_S` whose reading is nearest the measured one on the
    ``train`` samples of the windows that start on one (a window's start is its initial state);
    None when no τ can be fitted. The central difference reads one sample past a block's edge."""
    data = adapter.data
    y = data.p.astype(float)
    starts = reset_starts(data)
    rows = np.asarray(train, bool) & np.asarray(train, bool)[starts][windows(starts, data.n_samples)]
    best = (np.inf, None, None)
    for tau in FILTER_TAUS_S:
        inverted = replace(data, p=y + tau * np.gradient(y, data.time))
        try:
            fit = type(adapter)(inverted, adapter.volume_sensor, adapter.options).fit(terms, train, start_from)
        except FitError:  # the inverted pressure's noise is about τ / h times the reading's
            continue
        reading = through_filter(predict_with_resets(fit.params, inverted), y, starts, data.time, tau)
        miss = (reading - y)[rows]
        sse = float(np.sum(miss**2)) if np.isfinite(miss).all() else np.inf
        if sse < best[0]:
            best = (sse, tau, reading)
    return None if best[1] is None else best[1:]


def windows(starts: np.ndarray, n_samples: int) -> np.ndarray:
    """(T,) the index of the open-loop window each sample lies in, the windows starting at
    ``starts`` (:func:`~diegocal.pneumatic.predict.reset_starts`)."""
    return np.maximum(np.searchsorted(starts, np.arange(n_samples), side="right") - 1, 0)


def filter_rival(adapter, fitted, train, val, options: EngineOptions, exclude, term: Term):
    """(the filtered-sensor rival as a tested candidate, its evidence) when it beats ``term`` on
    the validation blocks' open-loop error (module docstring), else None. ``fitted``: the model
    the round's candidates were tested against; ``exclude``: readings the selection leaves out
    (of the test; the chamber's fits have no fault detector to leave any out of)."""
    name, data = adapter.unit_name, adapter.data
    if options.progress is not None:
        options.progress(f"judging {term.label} against a pressure sensor read through a filter")
    terms, train = adapter.terms(fitted), np.asarray(train, bool)
    found = filtered_readings(adapter, terms, train, fitted)
    if found is None:
        return None
    tau, reading = found
    y = data.p.astype(float).copy()
    if exclude and name in exclude:
        y[np.asarray(exclude[name], bool)] = np.nan
    now = adapter.open_loop(fitted)
    named = adapter.open_loop(adapter.fit(terms + (term,), train))
    # both judged on the same samples; a window's error carries through it: the windows are the units
    rows = np.asarray(val, bool) & np.isfinite(y) & np.isfinite(now) & np.isfinite(reading) & np.isfinite(named)
    idx = np.flatnonzero(rows)
    unit = windows(reset_starts(data), data.n_samples)[idx]
    rival = out_of_sample_test((y - now)[idx], (reading - now)[idx], idx, rows, unit)
    with_term = out_of_sample_test((y - now)[idx], (named - now)[idx], idx, rows, unit)
    threshold = critical_t(options.alpha, options.n_units, rival.df)
    significant = bool(rival.t > threshold and rival.gain >= options.unexplained_min_gain)
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
