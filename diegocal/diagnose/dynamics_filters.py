"""The sensor causes' fit (``torque_lag``, ``torque_gain``: :data:`diegocal.sgp.terms.FILTERS`):
each value by a bounded 1-D search with the linear parameters re-solved at every trial, and its
standard error marginal over them (a gain trades off with the inertial parameters). ``fit`` is the
:class:`~diegocal.diagnose.dynamics.DynamicsAdapter`; ``lags``: (joint row, cause) -> value."""

from __future__ import annotations

import numpy as np
from scipy.optimize import minimize_scalar

from diegocal.causes import cause as registry_cause
from diegocal.diagnose.dynamics_shapes import specs
from diegocal.lstsq import CHUNK_ROWS


def fit_filters(fit, A, lags: dict, train, sigma) -> dict:
    """Each filtering sensor's value (a lag's time constant in [0, MAX_LAG_S] s, a gain error
    within ±MAX_GAIN_ERROR: the registry's bounds) by bounded 1-D searches of the weighted
    training error, the linear parameters re-solved at every trial (two sweeps)."""
    lags = dict(lags)

    def cost(key, value):
        trial = dict(lags)
        trial[key] = value
        Aeff = fit._lagged(A, trial)
        offset = fit._offset(trial)
        w, _ = fit._solve(Aeff, train, sigma, offset)
        e = (fit.tau[train] - (Aeff @ w + offset)[train]) / sigma
        return float(np.nansum(e * e))

    for _ in range(2 if len(lags) > 1 else 1):
        for key in list(lags):
            spec = registry_cause(key[1]).parameters[0]
            res = minimize_scalar(
                lambda x, key=key: cost(key, x),
                bounds=(spec.lower, spec.upper),
                method="bounded",
                options={"xatol": 1e-4},
            )
            lags[key] = float(res.x)
    return lags


def filter_se(fit, model, w, t, lags: dict, pred, train, sigma) -> float:
    """Standard error of a filter term's value (a lag, s; a gain error), the linear parameters
    free: the prediction's derivative with respect to the value (central difference, the
    joint's other filters held), less its weighted least-squares fit by the model's columns on
    every joint's training rows (a gain trades off with the inertial parameters), against its
    joint's residual std; ``sigma`` (k,) the joints' weights (the fit's noise stds)."""
    A = model.features(fit.q, fit.qd, fit.qdd, sensors=False)  # before the sensors' filters, whole
    key, v = fit._key(t), float(t.values[0])
    r = key[0]
    h = max(1e-4, 0.01 * abs(v))
    lo = max(v - h, specs(t)[0].lower)
    own = {(0, c): x for (s, c), x in lags.items() if s == r}

    def joint_r(value):  # joint r's prediction with the term at ``value``
        trial = own | {(0, key[1]): value}
        out = fit._lagged(A[:, r : r + 1], trial)[:, 0] @ w
        if fit.inertia == "nominal":
            out += fit._lagged(fit.tau0[:, r : r + 1], trial)[:, 0]
        return out

    d = (joint_r(v + h) - joint_r(lo)) / (v + h - lo)
    ok = train & np.isfinite(fit.tau[:, r])
    e = fit.tau[ok, r] - pred[ok, r]
    X = fit._lagged(A, lags)
    P = X.shape[2]
    gram, xd, dd = np.zeros((P, P)), np.zeros(P), 0.0
    idx = np.flatnonzero(train)
    step = max(CHUNK_ROWS // X.shape[1], 1)
    for i in range(0, idx.size, step):
        rows = idx[i : i + step]
        Xw = X[rows] / sigma[None, :, None]
        good = np.isfinite(fit.tau[rows]) & np.isfinite(Xw).all(axis=2)
        Xw = np.where(good[:, :, None], Xw, 0.0)
        dw = np.where(good[:, r], d[rows] / sigma[r], 0.0)
        gram += np.einsum("tkp,tkq->pq", Xw, Xw)
        xd += Xw[:, r].T @ dw
        dd += float(dw @ dw)
    left = dd - float(xd @ np.linalg.pinv(gram) @ xd)
    if not left > 0:
        return float("nan")
    s2 = float(e @ e) / max(ok.sum() - 1, 1) / sigma[r] ** 2  # the joint's residual variance, weighted
    return float(np.sqrt(s2 / left))
