"""The valve-chamber model, thesis eq. (4.6)-(4.11), built from terms, and its exact step (4.7).

A :class:`ChamberModel` is the baseline terms of eq. (4.10) (:mod:`diegocal.pneumatic.terms`)
plus any extra terms. Inputs are sample arrays of one shape (T,) (or any common broadcast
shape): ``u`` valve voltage (V), ``v`` the normalised volume coordinate v' (see
:class:`~diegocal.pneumatic.params.ChamberParams`), ``vd`` its rate (1/s), ``p`` pressure
(pressure unit, "pu"), ``h`` time step (s), ``u_lags`` (T, L+1) the commands u_t, u_{t-1}, ...
(only a model with a ``valve_delay`` reads them). ``x`` is the packed vector of the model's
parameters in the order of :attr:`ChamberModel.names` (c1..c9 first);
``c_b, c_s, c_gamma`` are the fixed constants.

Note on the thesis: the compact form (4.11) writes the v-dot term of the rate as
``+ c5 vdot p / (1 + c6 v)``, while the sequential form (4.10e-f) gives
``(s - p) c5 vdot / (1 + c6 v)``. Only (4.10) has the form (4.6) ``pdot = (s - p) r`` that the
exact step (4.7) integrates, so we implement (4.10).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

import diegocal.pneumatic.terms as T
from diegocal.pneumatic.params import NAMES, ChamberParams


@dataclass(frozen=True)
class ModelTerms:
    """s(), r() and their parameter derivatives at each sample (thesis eq. 4.10).

    s, r : arrays (T,), steady-state pressure (pu) and rate (1/s), extra terms' flows folded in
    ds, dr : (T, P) d s / d x and d r / d x (None unless asked for); r is not clamped here
    s_p : d s / d p (T,) or 0.0 (0 unless a term makes s depend on the pressure)
    """

    s: np.ndarray
    r: np.ndarray
    ds: np.ndarray | None
    dr: np.ndarray | None
    s_p: np.ndarray | float = 0.0
    r_p: np.ndarray | float = 0.0


@dataclass(frozen=True)
class LineState:
    """The supply hose's sag Δ = P_c - P_s along N steps (a ``supply_droop`` of shape ``hose``).

    mean : (N,) the sag averaged over each step (pu), what the chamber's exact step reads
    start : (N,) the sag at each step's start (pu)
    dmean : (N, P) d mean / d x, or None
    """

    mean: np.ndarray
    start: np.ndarray
    dmean: np.ndarray | None = None

    def take(self, idx) -> LineState:
        """The steps ``idx`` of the series."""
        return LineState(self.mean[idx], self.start[idx], None if self.dmean is None else self.dmean[idx])


def sigmoid(x):
    """Quadratic sigmoid g(x) = x / sqrt(x² + 1), thesis eq. (4.8)."""
    return x / np.sqrt(x * x + 1.0)


def rate_shape(x, a, b, c):
    """k(x; a, b, c) = sqrt(x² + a²) - a + b + c x, thesis eq. (4.9)."""
    return np.sqrt(x * x + a * a) - a + b + c * x


class ChamberModel:
    """The baseline terms of eq. (4.10) plus ``extra`` terms (at most one per cause).

    Attributes
    ----------
    terms : every term, in evaluation order (inputs, steady state, rate, volume, flows, reading)
    extra : the extra terms as given
    names : parameter names, c1..c9 then the extra terms' (the packed vector's order)
    specs : (P,) their :class:`~diegocal.pneumatic.terms.ParamSpec`
    has_delay : whether the model reads lagged commands (:meth:`n_lags`)
    delay_at : positions of the delays in the packed vector (``sensor_lag``, ``valve_delay``): the
        valve holds the command for their sum late (a valve delay seen through the sensors' lag)
    """

    def __init__(self, extra=()):
        extra = T.chamber_terms(extra)
        causes = [t.cause for t in extra]
        dup = {c for c in causes if causes.count(c) > 1}
        if dup:
            raise ValueError(f"a chamber model takes one term per cause; {sorted(dup)} given twice")
        base = T.baseline_terms()
        self.extra = extra
        self.terms = tuple(sorted(base + extra, key=lambda t: T.part(t).stage))
        self.specs = T.BASELINE_SPECS + tuple(s for t in extra for s in T.specs_of(t))
        self.names = tuple(s.name for s in self.specs)
        self.index = {n: i for i, n in enumerate(self.names)}
        self.has_flow = any(T.part(t).stage == 5 for t in extra)
        self.offset_at = self.index.get("offset")
        self.has_delay = any(T.part(t).delay for t in extra)
        self.delay_at = [self.index[t.parameters[0].name] for t in extra if T.part(t).delay]
        self.hose = next((t for t in extra if t.cause == "supply_droop" and t.extra.get("shape") == "hose"), None)

    def n_lags(self, h: float) -> int:
        """Lagged commands the model reads at sample step ``h`` (s): 0 without a valve delay."""
        longest = T.MAX_DELAY_S + T.MAX_SENSOR_LAG_S
        return int(np.ceil(longest / h - 1e-9)) + 1 if self.has_delay else 0

    @property
    def n_params(self) -> int:
        return len(self.names)

    def lower(self) -> np.ndarray:
        return np.array([s.lower for s in self.specs])

    def upper(self) -> np.ndarray:
        return np.array([s.upper for s in self.specs])

    def start(self) -> np.ndarray:
        """Start values by name: Table 4.1's for c1..c9, the extra terms' own values."""
        x = np.array([s.start for s in self.specs])
        for t in self.extra:
            for p in t.parameters:
                x[self.index[p.name]] = p.value
        return x

    def evaluate(self, x, p, u, v, vd, h, c_b, c_s, c_gamma, jacobian=True, line=None) -> ModelTerms:
        """s and r of eq. (4.10) with every term added and the flows folded in (module doc of
        :mod:`~diegocal.pneumatic.terms`) for the command ``u`` the valve holds; ``p`` the model's
        pressure (the reading minus any offset); ``line`` the supply hose's :class:`LineState` over
        these steps (None: the hose at its equilibrium)."""
        x = np.asarray(x, float)
        shape = np.broadcast(u, v, vd).shape
        ev = T.Evaluation(x, self.index, p, u, v, vd, h, c_b, c_s, c_gamma, jacobian, shape=shape)
        if line is not None:
            ev.line, ev.dline = line.mean, line.dmean if jacobian else None
        for term in self.terms:
            T.part(term).add(term, ev)
        r = ev.num / ev.den  # (4.10e)
        dr = None
        if jacobian:
            den = ev.den[..., None] if np.ndim(ev.den) else ev.den
            dr = ev.dnum / den - (r[..., None] if np.ndim(r) else r) * ev.dden / den
        r_p = 0.0
        if ev.factor is not None:  # a shaping of the valve's rate (flow_saturation)
            r_p = r * ev.factor_p
            if jacobian:
                dr = dr * ev.factor[..., None] + r[..., None] * ev.dfactor
            r = r * ev.factor
        s, ds, s_p = ev.s, ev.ds, 0.0 if ev.s_p is None else ev.s_p
        if self.has_flow:  # (s - p) r + α - β p = (s' - p) r', r' = r + β, s' = (s r + α) / r'
            rc = np.maximum(r, 0.0)
            rc_p = np.where(r > 0, r_p, 0.0)
            r2 = rc + ev.beta
            safe = np.where(r2 > 0, r2, 1.0)
            s2 = np.where(r2 > 0, (s * rc + ev.alpha) / safe, s)
            if jacobian:
                drc = np.where((r > 0)[..., None], dr, 0.0)
                dr2 = drc + ev.dbeta
                ds = (ds * rc[..., None] + s[..., None] * drc + ev.dalpha - s2[..., None] * dr2) / safe[..., None]
                dr = dr2
            s_p = (s_p * rc + (s - s2) * rc_p + ev.alpha_p - s2 * ev.beta_p) / safe
            s, r, r_p = s2, r2, rc_p + ev.beta_p
        return ModelTerms(s, r, ds, dr, s_p, r_p)

    def _hose_load(self, x, p, u, v, vd, h, consts, jacobian):
        """x (N,) of the hose's ``supply_droop`` (:func:`~diegocal.pneumatic.terms.hose_load`) and
        d x / d x: the model's terms evaluated up to those that read the baseline's parts."""
        x = np.asarray(x, float)
        shape = np.broadcast(u, v, vd).shape
        ev = T.Evaluation(x, self.index, p, u, v, vd, h, *consts, jacobian, shape=shape)
        for term in self.terms:
            if T.part(term).stage >= 4:
                break
            T.part(term).add(term, ev)
        return T.hose_load(self.hose, ev)

    def _line_parts(self, x, p, u, v, vd, h, consts, jacobian):
        """The hose's step pieces: the equilibrium sag Δ* = (P_c - p) x / (1 + x), the decay e =
        exp(-λ h) of an exact step (4.7) at the rate λ = (1 + x) / τ, the step's mean weight m =
        (1 - e) / (λ h), and (with ``jacobian``) their derivatives in x."""
        tau = max(float(self.hose.extra["tau_s"]), 1e-12)
        pm = p if self.offset_at is None else p - x[self.offset_at]
        load, dload = self._hose_load(x, pm, u, v, vd, h, consts, jacobian)
        gap = consts[0] + consts[1] - pm  # P_c - p
        lam = (1.0 + load) / tau
        lh = lam * h
        e = np.exp(-lh)
        small = lh < 1e-8
        m = np.where(small, 1.0 - 0.5 * lh, -np.expm1(-lh) / np.where(small, 1.0, lh))
        q = load / (1.0 + load)
        star = gap * q
        if not jacobian:
            return star, e, m, None
        dstar = (gap / (1.0 + load) ** 2)[..., None] * dload
        if self.offset_at is not None:
            dstar[..., self.offset_at] += q  # d gap / d offset = 1
        dlam = dload / tau
        de = -(h * e)[..., None] * dlam
        dm = ((e - m) / lam)[..., None] * dlam
        return star, e, m, (dstar, de, dm)

    def line_step(self, x, sag, p, u, v, vd, h, c_b, c_s, c_gamma):
        """One exact step (4.7) of the supply hose's sag from ``sag`` (pu) at the step's start with
        the chamber at ``p``: (the sag averaged over the step, the sag at its end), no derivatives
        (open-loop prediction)."""
        star, e, m, _ = self._line_parts(np.asarray(x, float), p, u, v, vd, h, (c_b, c_s, c_gamma), False)
        return star + (sag - star) * m, star + (sag - star) * e

    def line(self, x, p, u, v, vd, h, c_b, c_s, c_gamma, reset=None, jacobian=False) -> LineState:
        """The supply hose's sag along a series of N consecutive steps, driven by the pressure ``p``
        (N,) and the commands at their starts (a ``supply_droop`` of shape ``hose``, module doc of
        :mod:`~diegocal.pneumatic.terms`).

        .. math:: \\tau \\dot\\Delta = x (P_c - p) - (1 + x) \\Delta

        is eq. (4.6)'s form, ``dΔ/dt = (Δ* - Δ) λ``: each step is the exact step (4.7) with x and p
        held, and the chamber reads the sag averaged over the step, Δ* + (Δ_t - Δ*) m. ``reset``
        (N,) bool: steps where the hose starts at its equilibrium (the series' first, after a gap);
        default the first only. With ``jacobian`` the derivatives in x (N, P) follow the same
        recursion (forward sensitivities)."""
        x = np.asarray(x, float)
        star, e, m, d = self._line_parts(x, p, u, v, vd, h, (c_b, c_s, c_gamma), jacobian)
        n = star.size
        reset = np.zeros(n, bool) if reset is None else np.asarray(reset, bool).copy()
        if n:
            reset[0] = True
        start = np.empty(n)
        sag = 0.0
        for t, (st, et, rt) in enumerate(zip(star.tolist(), e.tolist(), reset.tolist(), strict=True)):
            sag = st if rt else sag
            start[t] = sag
            sag = st + (sag - st) * et  # (4.7)
        mean = star + (start - star) * m
        if not jacobian:
            return LineState(mean, start)
        dstar, de, dm = d
        off = start - star
        push = dstar * (1.0 - e)[:, None] + off[:, None] * de  # d(start_{t+1}) = e d(start_t) + push
        ds = np.empty_like(dstar)
        row = dstar[0] if n else None
        for t in range(n):
            row = dstar[t] if reset[t] else row
            ds[t] = row
            row = e[t] * row + push[t]
        dmean = dstar * (1.0 - m)[:, None] + m[:, None] * ds + off[:, None] * dm
        return LineState(mean, start, dmean)

    def _exact_step(self, x, p, u, v, vd, h, consts, jacobian, line=None):
        """One exact step (4.7) with the command ``u`` held: p_next, d p_next / d x (or None),
        d p_next / d p, and s and max(r, 0) (for the derivative in the step's length)."""
        t = self.evaluate(x, p, u, v, vd, h, *consts, jacobian=jacobian, line=line)
        r = np.maximum(t.r, 0.0)
        e = np.exp(-r * h)
        p_next = t.s + (p - t.s) * e
        d_s = 1.0 - e  # d p_next / d s
        jac = None
        if jacobian:
            d_r = np.where(t.r > 0.0, -h * (p - t.s) * e, 0.0)  # d p_next / d r (0 where clamped)
            jac = d_s[..., None] * t.ds + d_r[..., None] * t.dr
        dp = e + d_s * t.s_p + np.where(t.r > 0.0, -h * (p - t.s) * e, 0.0) * t.r_p  # d p_next / d p
        return p_next, jac, dp, t.s, r

    def step(self, x, p, u, v, vd, h, c_b, c_s, c_gamma, u_lags=None, jacobian=True, line=None):
        """Exact step over h with s, r held fixed, thesis eq. (4.7): p(t+h) = s + (p - s) exp(-r h).

        ``p`` is the pressure reading at the step's start; ``u_lags`` (T, L+1) the commands u_t,
        u_{t-1}, ... (read only by a model with a valve delay, whose step is two exact steps, one
        per command the valve holds; ``valve_delay`` in :mod:`~diegocal.pneumatic.terms`); ``line``
        the supply hose's :class:`LineState` over these steps (:meth:`line`; a model with a hose
        needs it; the sag is held over the step, as the command is). Returns
        (p_next, J) with p_next of the samples' shape and J = d p_next / d x, shape (T, P) (None
        unless ``jacobian``).

        The rate is used as max(r, 0): §4.3 defines r() > 0 (a rate of convergence to s), but
        (4.10e) can turn negative where c5 vdot < -c7 k; a negative rate would make the step an
        exponential divergence from s, which no chamber does. Where r < 0 the pressure is held.
        """
        x = np.asarray(x, float)
        consts = (c_b, c_s, c_gamma)
        if self.hose is not None and line is None:
            raise ValueError("a model with a supply hose needs its sag over the steps (line)")
        offset = 0.0 if self.offset_at is None else float(x[self.offset_at])
        pm = p if self.offset_at is None else p - offset  # the sensor reads p + offset
        if not self.has_delay:
            p_next, jac, dp, _, _ = self._exact_step(x, pm, u, v, vd, h, consts, jacobian, line)
        else:
            if u_lags is None:
                raise ValueError("a model with a valve delay needs the lagged commands (u_lags)")
            D = np.clip(sum(x[i] for i in self.delay_at) / h, 0.0, u_lags.shape[-1] - 1 - 1e-9)
            n = np.floor(D).astype(int)
            f = D - n
            old = np.take_along_axis(u_lags, n[..., None] + 1, axis=-1)[..., 0]  # held first, f h
            new = np.take_along_axis(u_lags, n[..., None], axis=-1)[..., 0]  # then (1 - f) h
            p_mid, j1, dp1, s1, r1 = self._exact_step(x, pm, old, v, vd, f * h, consts, jacobian, line)
            p_next, j2, dp2, s2, r2 = self._exact_step(x, p_mid, new, v, vd, (1.0 - f) * h, consts, jacobian, line)
            dp = dp2 * dp1
            if jacobian:
                jac = j2 + dp2[..., None] * j1
                # d/d delay = (d/d f) / h; d p(τ)/d τ = r (s - p(τ)) at the end of an exact step
                d_delay = dp2 * r1 * (s1 - p_mid) - r2 * (s2 - p_next)
                for at in self.delay_at:
                    jac[..., at] = d_delay
        if self.offset_at is not None:
            p_next = p_next + offset
        if not jacobian:
            return p_next, None
        if self.offset_at is not None:  # d/d offset = 1 - d p_next / d p (+ the hose's, through its sag)
            jac[..., self.offset_at] += 1.0 - dp
        return p_next, jac


BASELINE = ChamberModel()


def model_of(params: ChamberParams) -> ChamberModel:
    """The chamber model of fitted parameters: the baseline plus their extra terms."""
    return ChamberModel(params.terms) if params.terms else BASELINE


def terms(x, u, v, vd, c_b, c_s, c_gamma, jacobian: bool = True) -> ModelTerms:
    """s() and r() of the baseline, thesis eq. (4.10a-e), with d/dc when ``jacobian``."""
    return BASELINE.evaluate(x, 0.0, u, v, vd, 1.0, c_b, c_s, c_gamma, jacobian)


def step_vector(x, p, u, v, vd, h, c_b, c_s, c_gamma, jacobian: bool = True):
    """The baseline's exact step (4.7), see :meth:`ChamberModel.step`; J is (T, 9)."""
    return BASELINE.step(x, p, u, v, vd, h, c_b, c_s, c_gamma, jacobian=jacobian)


def _inputs(params: ChamberParams, u, v, vd, u_lags=None):
    model = model_of(params)
    v, vd = params.volume_coordinate(v, vd)
    if model.has_delay and u_lags is None:  # a steady command: every lag is the command itself
        u_lags = np.repeat(np.asarray(u, float)[..., None], model.n_lags(0.01) + 1, axis=-1)
    return model, v, vd, u_lags


def pressure_rate(params: ChamberParams, p, u, v, vd):
    """pdot = (s - p) r, thesis eq. (4.6)/(4.10f), pu/s; v, vd raw sensor readings."""
    model, v, vd, lags = _inputs(params, u, v, vd)
    x = params.full_vector()
    off = 0.0 if model.offset_at is None else x[model.offset_at]
    t = model.evaluate(x, p - off, u, v, vd, 0.01, params.c_b, params.c_s, params.c_gamma, False)
    return (t.s - (p - off)) * t.r


def steady_state(params: ChamberParams, u, v=0.0, vd=0.0):
    """s(u, v, vdot), the steady-state pressure of thesis eq. (4.10c) as the sensor reads it, pu;
    v, vd raw readings. Should a term make s depend on p, the fixed point s = s(p = s)."""
    model, v, vd, lags = _inputs(params, u, v, vd)
    x = params.full_vector()
    off = 0.0 if model.offset_at is None else x[model.offset_at]
    consts = (params.c_b, params.c_s, params.c_gamma)
    s = model.evaluate(x, params.c_b, u, v, vd, 0.01, *consts, jacobian=False).s
    for _ in range(20):  # a no-op unless a term reads p
        s = model.evaluate(x, s, u, v, vd, 0.01, *consts, jacobian=False).s
    return s + off


def step(params: ChamberParams, p, u, v, vd, h, u_lags=None):
    """p(t+h) by thesis eq. (4.7) for a :class:`ChamberParams`; v, vd raw readings; ``u_lags``
    (T, L+1) the commands u_t, u_{t-1}, ... when the model has a valve delay
    (:meth:`~diegocal.pneumatic.data.ChamberData.u_lags`); with a supply hose the samples are one
    series of consecutive steps, the hose starting at its equilibrium (:meth:`ChamberModel.line`)."""
    model, v, vd, lags = _inputs(params, u, v, vd, u_lags)
    x, consts = params.full_vector(), (params.c_b, params.c_s, params.c_gamma)
    line = None
    if model.hose is not None:
        p, u, v, vd, h = (np.atleast_1d(np.asarray(a, float)) for a in np.broadcast_arrays(p, u, v, vd, h))
        line = model.line(x, p, u, v, vd, h, *consts)
    return model.step(x, p, u, v, vd, h, *consts, lags, False, line)[0]


__all__ = [
    "NAMES",
    "ChamberModel",
    "LineState",
    "ModelTerms",
    "model_of",
    "pressure_rate",
    "rate_shape",
    "sigmoid",
    "steady_state",
    "step",
    "step_vector",
    "terms",
]
