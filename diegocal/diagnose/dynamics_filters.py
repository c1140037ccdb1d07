"""The filter causes' fit (the sensors' ``torque_lag``, ``torque_gain``: :data:`diegocal.sgp.terms.
FILTERS`; a ``transmission_backlash``'s play, a filter of the model's angles: :mod:`diegocal.sgp.
backlash`): each value by a bounded 1-D search with the linear parameters re-solved at every trial,
and its standard error marginal over them (a gain trades off with the inertial parameters). ``fit``
is the :class:`~diegocal.diagnose.dynamics.DynamicsAdapter`; ``lags``: (joint row, cause) -> value."""

from __future__ import annotations

import numpy as np
from scipy.optimize import minimize_scalar

from diegocal.causes import cause as registry_cause
from diegocal.lstsq import CHUNK_ROWS
from diegocal.sgp.terms import FILTERS

#: A filter's search stops within this fraction of its registry range (a backlash's: 2e-6 rad): well
#: under its standard error (a fixed 1e-4 had been larger than a 0.02-rad backlash's ± of 6e-5 rad,
#: and the estimates strayed up to 4 SE from the truth).
SEARCH_TOL = 2e-5


def fit_filters(fit, terms, lags: dict, train, sigma) -> tuple[dict, np.ndarray]:
    """Each filter's value (a lag's time constant in [0, MAX_LAG_S] s, a gain error within
    ±MAX_GAIN_ERROR, a backlash's half-width in [0, MAX_BACKLASH_RAD] rad: the registry's bounds)
    by bounded 1-D searches of the weighted training error of the model with ``terms``, the
    linear parameters re-solved at every trial (two sweeps); a backlash's trial evaluates the
    model's columns at its link angles again. Searched with the weights ``sigma`` (k,) given (the
    model without the filters: the joints they act on under-weighted), then again with each
    joint's residual std at the values found, the weights the standard error assumes (with the
    first ones a backlash's estimates strayed up to 4 SE from the truth). Returns (the values,
    those weights)."""
    plain = fit._model_columns(terms, {})  # the columns at the logged angles
    lags = _search(fit, terms, lags, train, sigma, plain)
    sigma = _residual_std(fit, terms, lags, train, sigma, plain)
    return _search(fit, terms, lags, train, sigma, plain), sigma


def _residual(fit, terms, lags: dict, train, sigma, plain) -> np.ndarray:
    """(training rows, k) the residual of the model with ``terms`` at the filter values ``lags``,
    its linear parameters solved with the weights ``sigma``; ``plain``: the columns at the logged
    angles."""
    Aeff = fit._model_columns(terms, lags, plain)
    offset = fit._offset(lags)
    w, _ = fit._solve(Aeff, train, sigma, offset)
    return fit.tau[train] - (Aeff @ w + offset)[train]


def _residual_std(fit, terms, lags: dict, train, sigma, plain) -> np.ndarray:
    """(k,) each joint's training residual std of the model with ``terms`` at the filter values
    ``lags`` (the linear parameters solved with the weights ``sigma``)."""
    e = _residual(fit, terms, lags, train, sigma, plain)
    s = np.sqrt(np.nanmean(e * e, axis=0))
    return np.where(np.isfinite(s) & (s > 0), s, sigma)


def _search(fit, terms, lags: dict, train, sigma, plain) -> dict:
    """The bounded 1-D searches of :func:`fit_filters` with the weights ``sigma``."""
    lags = dict(lags)

    def cost(key, value):
        e = _residual(fit, terms, lags | {key: value}, train, sigma, plain) / sigma
        return float(np.nansum(e * e))

    for _ in range(2 if len(lags) > 1 else 1):
        for key in list(lags):
            spec = registry_cause(key[1]).parameters[0]
            res = minimize_scalar(
                lambda x, key=key: cost(key, x),
                bounds=(spec.lower, spec.upper),
                method="bounded",
                options={"xatol": SEARCH_TOL * (spec.upper - spec.lower)},
            )
            lags[key] = float(res.x)
    return lags


def filter_ses(fit, model, w, lags: dict, pred, train, sigma) -> dict:
    """Standard errors of the filter terms' values (a lag, s; a gain error; ``lags``: (row, cause)
    -> value), marginal over the linear parameters and each other: each value's derivative column
    (the prediction's central difference, its joint's other filters held) fitted with the model's
    columns on every joint's training rows, weighted by ``sigma`` (k,) (the fit's noise stds; a
    gain trades off with the inertial parameters, and gains on several joints with each other),
    scaled by the residual variance of the joints it is read from. A backlash's derivative column is on every joint (its
    play moves the link angle of the joints that carry it). Returns (row, cause) -> SE."""
    A = model.features(fit.q, fit.qd, fit.qdd, fit.time, sensors=False)  # before the sensors' filters, whole
    X = fit._lagged(A, lags)
    keys = list(lags)
    D = np.zeros((X.shape[0], X.shape[1], len(keys)))
    for f, key in enumerate(keys):
        if key[1] in FILTERS:
            D[:, key[0], f] = _derivative(fit, A, w, key, lags)
        else:  # a backlash: every joint's prediction moves
            D[:, :, f] = _play_derivative(fit, model, w, key, lags)
    var = marginal_variances(normal_matrix(X, D, fit.tau, train, sigma), X.shape[2])
    scale = read_variances(fit, D, pred, train, sigma, [key[0] for key in keys])
    return {key: float(np.sqrt(scale[f] * var[f])) if var[f] > 0 else float("nan") for f, key in enumerate(keys)}


def read_variances(fit, D: np.ndarray, pred: np.ndarray, train: np.ndarray, sigma: np.ndarray, own) -> np.ndarray:
    """(F,) the residual variance (weighted by ``sigma``) of the joints each of F values is read
    from, weighted by what each tells of it (its derivative column in D (T, k, F): a sensor's, its
    own joint's; a backlash's, every joint its play moves); ``own`` (F,) the row of each value's
    joint, read where its column is zero."""
    s2 = np.zeros(D.shape[1])  # each joint's residual variance, weighted
    for r in range(D.shape[1]):
        ok = train & np.isfinite(fit.tau[:, r])
        e = fit.tau[ok, r] - pred[ok, r]
        s2[r] = float(e @ e) / max(ok.sum() - 1, 1) / sigma[r] ** 2
    out = np.zeros(D.shape[2])
    for f in range(D.shape[2]):
        energy = np.nansum((D[train, :, f] / sigma[None, :]) ** 2, axis=0)
        out[f] = float(energy @ s2 / energy.sum()) if energy.sum() > 0 else float(s2[own[f]])
    return out


#: The filter values' information (the Schur complement of the model's columns) is singular when its
#: smallest eigenvalue is below this fraction of its largest: gains on every joint with identified
#: inertias (a common scale is theirs) have a direction the data do not fix.
SINGULAR = 1e-9


def normal_matrix(X: np.ndarray, D: np.ndarray, tau: np.ndarray, train: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """(P + F, P + F): the normal matrix of the model's columns X (T, k, P) and the derivative
    columns D (T, k, F), each joint weighted by ``sigma`` (k,), over the ``train`` rows (T,) where
    the joint's torque ``tau`` (T, k) and the columns are finite, CHUNK_ROWS rows at a time."""
    P = X.shape[2] + D.shape[2]
    gram = np.zeros((P, P))
    idx = np.flatnonzero(train)
    step = max(CHUNK_ROWS // X.shape[1], 1)
    for i in range(0, idx.size, step):
        rows = idx[i : i + step]
        Z = np.concatenate([X[rows], D[rows]], axis=2) / sigma[None, :, None]
        good = np.isfinite(tau[rows]) & np.isfinite(Z).all(axis=2)
        Z = np.where(good[:, :, None], Z, 0.0)
        gram += np.einsum("tkp,tkq->pq", Z, Z)
    return gram


def marginal_variances(gram: np.ndarray, p: int) -> np.ndarray:
    """(F,) the variances of the last F unknowns of the normal matrix ``gram`` with the first ``p``
    (the model's columns) free: the inverse of their Schur complement's diagonal, infinite for a
    value along a direction the data do not fix."""
    return marginal_covariance(gram, p)[1]


def marginal_covariance(gram: np.ndarray, p: int) -> tuple[np.ndarray, np.ndarray]:
    """((F, F), (F,)): the covariance and variances of the last F unknowns of ``gram`` with the first
    ``p`` free (:func:`complement_covariance` of their Schur complement)."""
    G_xx, G_xd, G_dd = gram[:p, :p], gram[:p, p:], gram[p:, p:]
    return complement_covariance(G_dd - G_xd.T @ np.linalg.pinv(G_xx) @ G_xd)


def complement_covariance(S: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """((F, F), (F,)): the inverse of a Schur complement ``S`` taken over the directions the data fix
    (eigenvalues above SINGULAR of the largest; zero along the others, so it is never indefinite),
    and the variances as :func:`marginal_variances` gives them (infinite along a direction not
    fixed): both from one decomposition."""
    vals, vecs = np.linalg.eigh(0.5 * (S + S.T))
    top = max(float(vals[-1]), 0.0)
    if top <= 0:
        return np.zeros_like(S), np.full(S.shape[0], np.inf)
    fixed = vals > SINGULAR * top
    var = (vecs[:, fixed] ** 2 / vals[fixed]) @ np.ones(int(fixed.sum()))
    loose = np.abs(vecs[:, ~fixed]).max(axis=1) > 1e-6 if (~fixed).any() else np.zeros(S.shape[0], bool)
    cov = (vecs[:, fixed] / vals[fixed]) @ vecs[:, fixed].T
    return cov, np.where(loose, np.inf, var)


def _derivative(fit, A, w, key, lags: dict) -> np.ndarray:
    """(T,) the derivative of joint ``key[0]``'s prediction with respect to the filter ``key``'s
    value (central difference within the registry's bounds, the joint's other filters held)."""
    r, cause = key
    own = {(0, c): x for (s, c), x in lags.items() if s == r}

    def joint_r(value):  # joint r's prediction with the term at ``value``
        trial = own | {(0, cause): value}
        out = fit._lagged(A[:, r : r + 1], trial)[:, 0] @ w
        if fit.inertia == "nominal":
            out += fit._lagged(fit.tau0[:, r : r + 1], trial)[:, 0]
        return out

    return _central_difference(joint_r, key, lags[key])


def _play_derivative(fit, model, w, key, lags: dict) -> np.ndarray:
    """(T, k) the derivative of every joint's prediction with respect to the backlash ``key``'s
    half-width (central difference within the registry's bounds, the other filters held): the
    model's columns evaluated at the link angles of each trial half-width."""

    def every_joint(value):  # the prediction with the half-width at ``value``
        trial = lags | {key: value}
        A = model.features(fit._angles(trial), fit.qd, fit.qdd, None, sensors=False)  # no time: angles as given
        return fit._lagged(A, trial) @ w + fit._offset(trial)

    return _central_difference(every_joint, key, lags[key])


def _central_difference(predict, key, v: float) -> np.ndarray:
    """The derivative of ``predict(value)`` at the filter ``key``'s value ``v``: a central
    difference of 1 % of it (at least 1e-4), its lower side kept within the registry's bounds."""
    h = max(1e-4, 0.01 * abs(v))
    lo = max(v - h, registry_cause(key[1]).parameters[0].lower)
    return (predict(v + h) - predict(lo)) / (v + h - lo)
