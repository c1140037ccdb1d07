"""The nonlinear parameters of dynamics terms, searched with the linear ones re-solved at every
trial: shape parameters (a Stribeck velocity scale) and where a position friction acts (its
region's edges refined on the training data, their uncertainty carried into the friction's
standard errors: the proposals' windows are bins of the joint's range, and an edge a bin off
biases the coefficients beyond their standard errors).

``fit`` is the :class:`diegocal.diagnose.dynamics.DynamicsAdapter` in hand (its data and its
weighted least squares)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.optimize import minimize_scalar

from diegocal.causes import cause as registry_entry
from diegocal.diagnose.dynamics_filters import complement_covariance, normal_matrix, read_variances
from diegocal.diagnose.dynamics_system import feature_chunks
from diegocal.sgp.terms import columns, is_filter

#: edges are refined over REGION_STEPS points within REGION_SPAN proposal bins either side
REGION_STEPS = 33
REGION_SPAN = 2.0


def refine_regions(fit, terms, lags: dict, train, sigma) -> tuple:
    """Each position friction's inner edges (not one open to a joint limit) moved to the least
    weighted training error on a grid of REGION_STEPS points within REGION_SPAN of the
    proposal's bin width either side: the proposals' windows are bins of the range, and an
    edge a bin off biases the friction's coefficients beyond their standard errors."""
    terms = list(terms)
    for i, t in enumerate(terms):
        if t.cause != "position_friction":
            continue
        col = fit.robot.joint_index(t.channel)
        x = fit.q[train, col]
        lo, hi = float(np.min(x)), float(np.max(x))
        step = REGION_SPAN * (hi - lo) / 64.0
        for edge in ("low", "high"):
            r = terms[i].region
            value = getattr(r, edge)
            if value <= lo or value >= hi:  # open to the limit, or at the data's end
                continue
            grid = np.linspace(value - step, value + step, REGION_STEPS)
            if edge == "low":
                grid = grid[grid < r.high]
            else:
                grid = grid[grid > r.low]
            costs = np.array(
                [
                    fit._cost(
                        terms[:i] + [replace(terms[i], region=replace(r, **{edge: float(g)}))] + terms[i + 1 :],
                        lags,
                        train,
                        sigma,
                    )
                    for g in grid
                ]
            )
            best = int(np.argmin(costs))
            # the edges whose error is within one (weighted, chi-square) unit: its standard error
            near = grid[costs <= costs[best] + 1.0]
            se = max(0.5 * float(near.max() - near.min()), float(grid[1] - grid[0]))
            extra = {**terms[i].extra, f"{edge}_stderr": se}
            terms[i] = replace(terms[i], region=replace(r, **{edge: float(grid[best])}), extra=extra)
    return tuple(terms)


def with_region_se(fit, term, terms, lags: dict, train, sigma):
    """``term`` (a position friction) with standard errors that carry its region's: each
    parameter's change when an inner edge moves by its standard error (``extra``), added in
    quadrature to the fit's own."""
    i = next(k for k, t in enumerate(terms) if t is term or (t.cause == term.cause and t.channel == term.channel))
    base = linear_values(fit, terms, i, lags, train, sigma)
    extra_var = np.zeros(len(term.linear))
    for edge in ("low", "high"):
        se = term.extra.get(f"{edge}_stderr")
        if se is None:
            continue
        for sign in (-1.0, 1.0):
            moved = replace(term, region=replace(term.region, **{edge: getattr(term.region, edge) + sign * se}))
            trial = terms[:i] + (moved,) + terms[i + 1 :]
            extra_var += 0.5 * (linear_values(fit, trial, i, lags, train, sigma) - base) ** 2
    se = np.sqrt(np.array([p.stderr for p in term.linear]) ** 2 + extra_var)
    return term.with_linear_values([p.value for p in term.linear], se)


def linear_values(fit, terms, i: int, lags: dict, train, sigma) -> np.ndarray:
    """The weighted least-squares values of term ``i``'s linear parameters in a model of ``terms``."""
    w, _ = fit._weighted_fit(terms, lags, train, sigma)
    at = fit.base.n_base + sum(len(t.linear) for t in terms[:i] if not is_filter(t))
    return w[at : at + len(terms[i].linear)]


def fit_shapes(fit, terms, lags: dict, train, sigma) -> tuple:
    """Each shape parameter of ``terms`` (:mod:`diegocal.causes`: a Stribeck velocity scale, a
    spring's rest angle) by a bounded 1-D search of the weighted training error with the linear
    parameters re-solved at every trial (one sweep per parameter, two when there are several): a
    scale in log space between its bounds, an angle over the joint's training range widened by
    its width either side. A shape the model cannot tell (:func:`held_shapes`) keeps its value."""
    terms = list(terms)
    slots = [(i, p) for i, t in enumerate(terms) for p in specs(t) if p.shape and p.name not in held_shapes(t, terms)]

    def cost(i, name, x, log):
        trial = list(terms)
        trial[i] = with_value(trial[i], name, float(np.exp(x) if log else x))
        return fit._cost(trial, lags, train, sigma)

    for _ in range(2 if len(slots) > 1 else 1):
        for i, spec in slots:
            log = spec.lower > 0
            if log:
                bounds, xatol = (np.log(spec.lower), np.log(spec.upper)), 1e-3
            else:
                x = fit.q[train, fit.robot.joint_index(terms[i].channel)]
                lo, hi = float(np.min(x)), float(np.max(x))
                bounds, xatol = (2 * lo - hi, 2 * hi - lo), 1e-4 * max(hi - lo, 1e-3)
            res = minimize_scalar(
                lambda x, i=i, n=spec.name, g=log: cost(i, n, x, g),
                bounds=bounds,
                method="bounded",
                options={"xatol": xatol},
            )
            terms[i] = with_value(terms[i], spec.name, float(np.exp(res.x) if log else res.x))
    return tuple(terms)


def held_shapes(term, terms) -> frozenset:
    """The shape parameters of ``term`` that ``terms`` leave undetermined: a spring's rest angle
    beside a torque offset on its joint (moving the rest shifts the spring's torque by a constant,
    which the offset takes back)."""
    if term.cause == "spring" and any(t.cause == "torque_offset" and t.channel == term.channel for t in terms):
        return frozenset({"rest_angle"})
    return frozenset()


def with_shape_se(fit, term, model, pred, rows):
    """``term`` with standard errors marginal over its shape parameters and the model's columns:
    each shape parameter's derivative column (the prediction's central difference in it, on each
    joint the term moves: a coupled motor's two) beside the model's columns on every joint's
    training ``rows``, weighted by the fit's noise stds; a shape parameter's variance is the
    inverse normal matrix's (the Schur complement of the model's columns) times the residual
    variance of the joints it is read from (:func:`read_variances`), and the term's linear
    parameters' standard errors widen by what the shape's uncertainty adds to theirs. Held at the
    shape found instead, a Stribeck velocity scale's ± ignored its trade-off with the amplitude
    (their errors run opposite ways): ± coverage 0.78 over 49 logs."""
    r = fit.row_of.get(term.channel)
    fixed = held_shapes(term, model.terms)  # no standard error: the data do not determine them
    term = replace(term, parameters=tuple(replace(p, stderr=float("nan")) if p.name in fixed else p
                                          for p in term.parameters))
    shapes = [p for p in specs(term) if p.shape and p.name not in fixed]
    if r is None or not shapes:
        return term
    amp = np.array([p.value for p in term.linear])
    D = np.zeros((len(fit.time), len(fit.rows), len(shapes)))
    for f, spec in enumerate(shapes):
        v = term.value(spec.name)
        h = 0.01 * v if spec.lower > 0 else 0.01  # a scale's step relative; an angle's in rad
        up, down = (
            columns(with_value(term, spec.name, x), fit.robot, fit.q, fit.qd, fit.qdd)[:, fit.rows]
            for x in (v + h, v - h)
        )
        D[:, :, f] = (up - down) @ amp / (2 * h)
    sigma = np.sqrt(np.asarray(model.gp_.noise_var_, float)).reshape(-1)
    gram = sum(  # the model's columns (T, k, P) a chunk of training samples at a time, never whole
        normal_matrix(A, D[at], fit.tau[at], np.ones(at.size, bool), sigma)
        for at, A in feature_chunks(model, fit, np.flatnonzero(rows))
    )
    P = gram.shape[0] - len(shapes)
    G_xx, G_xd = gram[:P, :P], gram[:P, P:]
    held = np.linalg.pinv(G_xx)
    B = held @ G_xd  # how each column's value moves with the shapes
    # the shapes' covariance, the model's columns free, and their variances from one Schur complement
    # (two products of it in different orders had disagreed in sign where the shape's derivative is
    # nearly a model column: a negative widening, a NaN ±)
    S_inv, var = complement_covariance(gram[P:, P:] - G_xd.T @ B)
    s2 = read_variances(fit, D, pred, rows, sigma, [r] * len(shapes))
    S_inv = S_inv if np.isfinite(var).all() else np.zeros_like(S_inv)
    at = _columns_at(model, term)
    lin = slice(at, at + len(term.linear))
    added = np.einsum("if,fg,ig->i", B[lin], S_inv, B[lin])  # the linear parameters' variance the shapes add
    widen = np.sqrt(1.0 + added / np.diag(held)[lin])
    out = term.with_linear_values(amp, [p.stderr * w for p, w in zip(term.linear, widen, strict=True)])
    se = {p.name: float(np.sqrt(s * x)) if x > 0 else float("nan") for p, s, x in zip(shapes, s2, var, strict=True)}
    return replace(out, parameters=tuple(replace(p, stderr=se.get(p.name, p.stderr)) for p in out.parameters))


def _columns_at(model, term) -> int:
    """Where ``term``'s linear columns start in the model's (after the base parameters; a filter
    term has none)."""
    at = model.base_.n_base
    for t in model.terms:
        if (t.cause, t.channel, t.region) == (term.cause, term.channel, term.region):
            return at
        at += 0 if is_filter(t) else len(t.linear)
    raise ValueError(f"{term.label} is not a term of the model")


def specs(term):
    """The registry's parameter specs of a term's cause."""
    return registry_entry(term.cause).parameters


def with_value(term, name: str, value: float):
    """``term`` with parameter ``name`` set to ``value``."""
    return replace(term, parameters=tuple(replace(p, value=value) if p.name == name else p for p in term.parameters))
