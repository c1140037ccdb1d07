"""The 9-parameter valve-chamber model, thesis eq. (4.6)-(4.11), and its exact step (4.7).

Inputs are sample arrays of one shape (T,) (or any common broadcast shape):
``u`` valve voltage (V), ``v`` the normalised volume coordinate v' (see
:class:`~diegocal.pneumatic.params.ChamberParams`), ``vd`` its rate (1/s),
``p`` pressure (pressure unit, "pu"), ``h`` time step (s). ``x`` is the packed vector c1..c9
(:data:`diegocal.pneumatic.params.NAMES`); ``c_b, c_s, c_gamma`` are the fixed constants.

Note on the thesis: the compact form (4.11) writes the v-dot term of the rate as
``+ c5 vdot p / (1 + c6 v)``, while the sequential form (4.10e-f) gives
``(s - p) c5 vdot / (1 + c6 v)``. Only (4.10) has the form (4.6) ``pdot = (s - p) r`` that the
exact step (4.7) integrates, so we implement (4.10).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from diegocal.pneumatic.params import ChamberParams


@dataclass(frozen=True)
class ModelTerms:
    """s(), r() and their parameter derivatives at each sample (thesis eq. 4.10).

    s, r : arrays (T,), steady-state pressure (pu) and rate (1/s)
    ds : (T, 9) d s / d c (non-zero in c1..c4); dr : (T, 9) d r / d c (c1, c5..c9)
    """

    s: np.ndarray
    r: np.ndarray
    ds: np.ndarray | None
    dr: np.ndarray | None


def sigmoid(x):
    """Quadratic sigmoid g(x) = x / sqrt(x² + 1), thesis eq. (4.8)."""
    return x / np.sqrt(x * x + 1.0)


def rate_shape(x, a, b, c):
    """k(x; a, b, c) = sqrt(x² + a²) - a + b + c x, thesis eq. (4.9)."""
    return np.sqrt(x * x + a * a) - a + b + c * x


def terms(x, u, v, vd, c_b, c_s, c_gamma, jacobian: bool = True) -> ModelTerms:
    """Evaluate s() and r() of thesis eq. (4.10a-e), with d/dc when ``jacobian``."""
    c1, c2, c3, c4, c5, c6, c7, c8, c9 = (float(c) for c in x)
    uh = u - c1  # (4.10a)
    a = c2 * uh + c3 * uh**3
    root = np.sqrt(a * a + 1.0)
    g = a / root  # (4.10b)
    s = c_b + c_s * g + c4 * vd  # (4.10c)
    ru = np.sqrt(uh * uh + c_gamma * c_gamma)
    k = ru - c_gamma + c9 + c8 * uh  # (4.10d), k(uh; c_gamma, c9, c8)
    den = 1.0 + c6 * v
    num = c7 * k + c5 * vd
    r = num / den  # (4.10e)
    if not jacobian:
        return ModelTerms(s, r, None, None)
    shape = np.broadcast(u, v, vd).shape
    ds = np.zeros((*shape, 9))
    dr = np.zeros((*shape, 9))
    dg = c_s / root**3  # c_s dg/da
    ds[..., 0] = -dg * (c2 + 3.0 * c3 * uh**2)
    ds[..., 1] = dg * uh
    ds[..., 2] = dg * uh**3
    ds[..., 3] = vd
    dr[..., 0] = -c7 * (uh / ru + c8) / den
    dr[..., 4] = vd / den
    dr[..., 5] = -r * v / den
    dr[..., 6] = k / den
    dr[..., 7] = c7 * uh / den
    dr[..., 8] = c7 / den
    return ModelTerms(s, r, ds, dr)


def pressure_rate(params: ChamberParams, p, u, v, vd):
    """pdot = (s - p) r, thesis eq. (4.6)/(4.10f), pu/s; v, vd raw sensor readings."""
    v, vd = params.volume_coordinate(v, vd)
    t = terms(params.vector(), u, v, vd, params.c_b, params.c_s, params.c_gamma, jacobian=False)
    return (t.s - p) * t.r


def steady_state(params: ChamberParams, u, v=0.0, vd=0.0):
    """s(u, v, vdot), the steady-state pressure of thesis eq. (4.10c), pu; v, vd raw readings."""
    v, vd = params.volume_coordinate(v, vd)
    return terms(
        params.vector(), u, v, vd, params.c_b, params.c_s, params.c_gamma, jacobian=False
    ).s


def step_vector(x, p, u, v, vd, h, c_b, c_s, c_gamma, jacobian: bool = True):
    """Exact step over h with s, r held fixed, thesis eq. (4.7): p(t+h) = s + (p - s) exp(-r h).

    Returns (p_next, J) with p_next of the samples' shape and J = d p_next / d c, shape (T, 9)
    (None unless ``jacobian``).

    The rate is used as max(r, 0): §4.3 defines r() > 0 (a rate of convergence to s), but
    (4.10e) can turn negative where c5 vdot < -c7 k; a negative rate would make the step an
    exponential divergence from s, which no chamber does. Where r < 0 the pressure is held.
    """
    t = terms(x, u, v, vd, c_b, c_s, c_gamma, jacobian)
    r = np.maximum(t.r, 0.0)
    e = np.exp(-r * h)
    p_next = t.s + (p - t.s) * e
    if not jacobian:
        return p_next, None
    d_s = 1.0 - e  # d p_next / d s
    d_r = np.where(t.r > 0.0, -h * (p - t.s) * e, 0.0)  # d p_next / d r (0 where clamped)
    jac = d_s[..., None] * t.ds + d_r[..., None] * t.dr
    return p_next, jac


def step(params: ChamberParams, p, u, v, vd, h):
    """p(t+h) by thesis eq. (4.7) for a :class:`ChamberParams`; v, vd raw readings."""
    v, vd = params.volume_coordinate(v, vd)
    return step_vector(
        params.vector(), p, u, v, vd, h, params.c_b, params.c_s, params.c_gamma, False
    )[0]
