"""What the pneumatics adapter's chamber fits carry beyond their values (:mod:`diegocal.diagnose.
pneumatics`): a valve delay's ± with the held sensor lag's, a pressure offset's with the model's own
error in an offset, the pressure sensor's span error a lasting supply sag equals."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from diegocal.pneumatic.params import NAMES

#: The 9-parameter model's own error in a pressure offset, as a fraction of P_c - P_r: the RMS of
#: the offset the model refitted with the term finds on clean chambers (the project's thin-plate
#: simulator, diego, three 60-s logs of 76 chambers: 0.68-0.70 kPa at P_c - P_r = 520 kPa, mean
#: +0.48, at most 2.2). How much of the model's error an offset takes up depends on the chamber
#: and the session's path, which the fit's within-session standard error cannot see (it covered
#: the truth 0.50 / 0.36 of the time on two generators); it is added to the offset's variance.
MODEL_OFFSET = 0.0013


def with_sensor_lag(fit, se_lag: float):
    """``fit`` with the held sensor lag's standard error ``se_lag`` (s) added to the valve delay's
    (whose estimate is the delay beyond that lag: their correlation is negative), the lag's set to
    it, and their correlation written into the valve delay's ``extra``."""
    names = list(fit.params.names())
    i, j = names.index("delay_s"), names.index("lag_s")
    cov = np.array(fit.covariance, float)
    cov[i, i] += se_lag**2
    cov[j, j] = se_lag**2
    cov[i, j] = cov[j, i] = -(se_lag**2)
    corr = float(cov[i, j] / np.sqrt(cov[i, i] * cov[j, j]))
    return _with_covariance(fit, cov, "valve_delay", {"correlation": {"sensor_lag.lag_s": round(corr, 4)}})


def with_model_error(fit, span: float):
    """``fit`` with the model's own error in a pressure offset (:data:`MODEL_OFFSET` of ``span`` =
    P_c - P_r) added to the offset's variance and written into its ``extra`` (``model_error``)."""
    sd = MODEL_OFFSET * span
    cov = np.array(fit.covariance, float)
    i = list(fit.params.names()).index("offset")
    cov[i, i] += sd**2
    return _with_covariance(fit, cov, "pressure_offset", {"model_error": round(sd, 4)})


#: The valve's parameters whose correlation with a leak's or a sag's estimate is written beside it
#: (``extra.correlation``) when at least this in size: the trade the ± (joint over c1..c9, so
#: already marginal over them) cannot show as a bias (:func:`with_trades`).
TRADE_MIN = 0.3


def with_trades(fit, cause: str):
    """``fit`` with the correlations of the ``cause`` term's first parameter with the baseline's
    c1..c9 that are at least :data:`TRADE_MIN` in size written into the term's ``extra``
    (``correlation: {c1: ρ, ...}``).

    Why: on the independent thin-plate generator a chamber leak's ± (cluster-robust, over all
    parameters: no conditional one) covered the orifice's rate in 0 of 32 logs (the orifice shape
    gave 0.13-0.41 of it, the linear 0.28-1.32): refitted with an orifice leak held at its true
    rate, two such logs fit worse than with a quarter of it, with c1 0.09-0.13 V lower; the valve's
    centre takes the rest (eq. 4.10's own error, not sampling, decides the trade). The correlation
    says which parameter the estimate trades with."""
    if fit.covariance is None:
        return fit
    term = next((t for t in fit.params.terms if t.cause == cause), None)
    if term is None:
        return fit
    mine = term.parameters[0].name
    pairs = {n: fit.correlation(mine, n) for n in NAMES}
    pairs = {n: round(r, 3) for n, r in pairs.items() if np.isfinite(r) and abs(r) >= TRADE_MIN}
    return replace(fit, params=_with_extra(fit.params, cause, {"correlation": pairs}))


def _with_covariance(fit, cov: np.ndarray, cause: str, extra: dict):
    """``fit`` with the covariance ``cov`` (its standard errors rewritten) and ``extra`` added to
    the ``cause`` term's."""
    se = np.sqrt(np.maximum(np.diag(cov), 0.0))
    params = _with_extra(fit.params.from_vector(fit.params.full_vector(), se), cause, extra)
    return replace(fit, params=params, covariance=cov)


def _with_extra(params, cause: str, extra: dict):
    """Chamber parameters ``params`` with ``extra`` added to the ``cause`` term's."""
    return params.with_terms(tuple(replace(t, extra={**t.extra, **extra}) if t.cause == cause else t
                                   for t in params.terms))


def with_span_error(params, span: float):
    """A lasting supply sag Δ written with the pressure sensor's span error it equals, −Δ / ``span``
    (``extra.span_error``): to eq. (4.10) the two are one model. A sensor reading
    P_r + (1 + k)(p - P_r) sees the valve's target s moved by k (s - P_r) = k span f + k c4 v̇ (f the
    supply's share), which a sag Δ = -k span and c4 (1 + k) make exactly; the rate r is unchanged but
    for the ports' flow saturation, which sat / (1 + k) keeps. Exact for the baseline and every term
    but an orifice-shaped leak, whose flow depends on the pressure itself."""
    droop = next(float(t.values[0]) for t in params.terms if t.cause == "supply_droop")
    return _with_extra(params, "supply_droop", {"span_error": round(-droop / span, 6)})
