"""The pneumatic behaviour of the causes (:mod:`diegocal.causes`): what each term adds to eq. (4.10).

The chamber model is ``pdot = (s - p) r`` (thesis eq. 4.6) with

.. math::

    s = c_b + \\sum_i s_i, \\qquad r = \\frac{\\sum_i n_i}{1 + \\sum_i d_i}

and each term adds its parts ``s_i`` (steady-state pressure), ``n_i`` (the rate's numerator) or
``d_i`` (its volume denominator), with their derivatives in every parameter, into an
:class:`Evaluation`. The nine parameters c1..c9 of Table 4.1 are five baseline terms, grouped by
what they model in eq. (4.10):

==========================  ===========  ==============================================
term (``cause``)            parameters   part of eq. (4.10)
==========================  ===========  ==============================================
``valve_steady_state``      c1 c2 c3     s += c_s g(c2 û + c3 û³), û = u - c1 (4.10a-c)
``volume_rate_steady``      c4           s += c4 v̇ (4.10c)
``valve_rate``              c7 c8 c9     n += c7 k(û; c_γ, c9, c8) (4.10d-e; reads c1)
``volume_rate_rate``        c5           n += c5 v̇ (4.10e)
``chamber_volume``          c6           d += c6 v (4.10e)
==========================  ===========  ==============================================

Their parameters, units and bounds are the registry's. Extra terms (``diagnose``'s vocabulary;
channel = the chamber) keep the form (4.6), so that the exact step (4.7) still applies:

- ``valve_delay`` (delay_s, s): the valve answers the command ``delay_s`` late: within a step the
  valve holds first the older command, then the newer one, and the model takes one exact step
  (4.7) per piece;
- ``chamber_leak`` (leak, 1/s): air escapes to the room, an added outflow
  ``-leak Φ(p) / (1 + c6 v)`` (a flow into a chamber of volume ∝ 1 + c6 v), Φ a thin-plate
  orifice's outflow (``extra: {shape: orifice}``) or p - P_r;
- ``supply_droop`` (droop, pressure unit): the supply sags while the valve draws from it: s loses
  ``f Δ`` with f = (1 + g)/2 the supply's share of the port flow, Δ = droop (``share``) or the sag
  of a line resistance that carries the port's flow (``extra: {shape: flow}``), or the sag of a
  hose that line feeds, a state of its own (``extra: {shape: hose, tau_s: ...}``,
  :meth:`~diegocal.pneumatic.model.ChamberModel.line`);
- ``pressure_offset`` (offset, pressure unit): the sensor reads p + offset; the model runs on the
  reading minus the offset;
- ``sensor_lag`` (lag_s, s; at most one tick): the tick-averaged pressure answers the command a
  fraction of a tick late (thesis §4.5); the form of ``valve_delay``, to which it adds;
- ``flow_saturation`` (sat, 1): the valve's rate r becomes r / (1 + sat |s - p| / c_s): the
  thin-plate flow (4.1) is choked far from equilibrium, less than proportional to s - p.

Folding the flows into (s, r): ``(s - p) r + α - β p = (s' - p) r'`` with r' = r + β and
s' = (s r + α) / r'.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from diegocal.causes import C1, C2, C3, C4, C5, C6, C7, C8, C9, MAX_DELAY_S, MAX_SENSOR_LAG_S, causes_of
from diegocal.causes import cause as registry_entry
from diegocal.errors import InputFileError
from diegocal.terms import Term, make_term

__all__ = ["MAX_DELAY_S", "MAX_SENSOR_LAG_S"]  # the registry's limits, re-exported for the model

@dataclass
class Evaluation:
    """Work space of one evaluation of the model on N samples; the terms add into it.

    Inputs: ``x`` (P,) parameter values in the model's layout (``index``: name -> position);
    ``p`` (N,) pressure at the step's start (pu); ``u`` (N,) valve command (V); ``v``, ``vd`` (N,)
    the normalised volume coordinate and its rate; ``h`` (N,) step, s; ``c_b, c_s, c_gamma`` the
    fixed constants.

    Parts (N,) and their derivatives (N, P) (None unless ``jacobian``): ``s``/``ds`` the steady
    state, ``num``/``dnum`` and ``den``/``dden`` the rate's numerator and denominator, ``g``/``dg``
    the valve sigmoid, ``alpha``/``beta`` the flows added to ``pdot`` as ``alpha - beta p`` (None
    until a term adds one), ``s_p`` d s / d p (None: 0), ``factor``/``factor_p``/``dfactor`` a
    factor of the valve's rate num/den, its derivative in p and in x (None: 1); ``line``/``dline``
    (N,), (N, P) the supply hose's sag over each step (pu) and its derivative, an input of a
    ``supply_droop`` of shape ``hose`` (None: the hose at its equilibrium, the flow shape's sag).
    """

    x: np.ndarray
    index: dict
    p: np.ndarray
    u: np.ndarray
    v: np.ndarray
    vd: np.ndarray
    h: np.ndarray
    c_b: float
    c_s: float
    c_gamma: float
    jacobian: bool
    uh: np.ndarray | None = None
    s: np.ndarray | None = None
    ds: np.ndarray | None = None
    g: np.ndarray | None = None
    dg: np.ndarray | None = None
    num: np.ndarray | None = None
    dnum: np.ndarray | None = None
    den: np.ndarray | None = None
    dden: np.ndarray | None = None
    alpha: np.ndarray | None = None
    dalpha: np.ndarray | None = None
    beta: np.ndarray | None = None
    dbeta: np.ndarray | None = None
    alpha_p: np.ndarray | float = 0.0
    beta_p: np.ndarray | float = 0.0
    s_p: np.ndarray | None = None
    factor: np.ndarray | None = None
    factor_p: np.ndarray | None = None
    dfactor: np.ndarray | None = None
    shape: tuple = field(default=())
    line: np.ndarray | None = None
    dline: np.ndarray | None = None

    def value(self, name: str) -> float:
        return float(self.x[self.index[name]])

    def zeros(self) -> np.ndarray:
        return np.zeros((*self.shape, self.x.size))

    @property
    def supply(self) -> float:
        return self.c_b + self.c_s

    @property
    def room(self) -> float:
        return self.c_b - self.c_s

    def add_flow(self, alpha, beta, dalpha=None, dbeta=None, alpha_p=0.0, beta_p=0.0) -> None:
        """Add ``alpha - beta p`` to pdot (pu/s); derivatives (N, P) when ``jacobian``; ``alpha_p``,
        ``beta_p``: their derivatives in the pressure at the step's start (a flow linearised there)."""
        self.alpha = alpha if self.alpha is None else self.alpha + alpha
        self.beta = beta if self.beta is None else self.beta + beta
        self.alpha_p = self.alpha_p + alpha_p
        self.beta_p = self.beta_p + beta_p
        if self.jacobian:
            self.dalpha = dalpha if self.dalpha is None else self.dalpha + dalpha
            self.dbeta = dbeta if self.dbeta is None else self.dbeta + dbeta


@dataclass(frozen=True)
class Part:
    """How a cause enters the chamber model: ``add(term, ev)`` adds its parts to an
    :class:`Evaluation`; ``stage`` orders the terms in an evaluation: inputs (0), steady state (1),
    rate numerator (2), volume (3), terms that read the baseline's parts (4), flows (5), the sensor
    reading (6); ``delay``: the model splits each step at the command's delay
    (:meth:`~diegocal.pneumatic.model.ChamberModel.step`) instead."""

    stage: float
    add: Callable[[Term, Evaluation], None]
    delay: bool = False


# ----------------------------------------------------------------------------- baseline (Table 4.1)
def _valve_steady_state(term: Term, ev: Evaluation) -> None:
    """s += c_s g(c2 û + c3 û³), û = u - c1: the valve's steady state, thesis eq. (4.10a-c)."""
    c1, c2, c3 = (ev.value(n) for n in ("c1", "c2", "c3"))
    uh = ev.u - c1  # (4.10a)
    a = c2 * uh + c3 * uh**3
    root = np.sqrt(a * a + 1.0)
    ev.uh, ev.g = uh, a / root  # (4.10b)
    ev.s = ev.c_b + ev.c_s * ev.g  # (4.10c)
    if ev.jacobian:
        i1, i2, i3 = (ev.index[n] for n in ("c1", "c2", "c3"))
        dg = 1.0 / root**3  # dg/da
        ev.dg = ev.zeros()
        ev.dg[..., i1] = -dg * (c2 + 3.0 * c3 * uh**2)
        ev.dg[..., i2] = dg * uh
        ev.dg[..., i3] = dg * uh**3
        dgs = ev.c_s / root**3  # c_s dg/da: ds, written as (4.10) is differentiated
        ev.ds = ev.zeros()
        ev.ds[..., i1] = -dgs * (c2 + 3.0 * c3 * uh**2)
        ev.ds[..., i2] = dgs * uh
        ev.ds[..., i3] = dgs * uh**3


def _volume_rate_steady(term: Term, ev: Evaluation) -> None:
    """s += c4 v̇: the volume rate drives the steady state, thesis eq. (4.10c)."""
    ev.s = ev.s + ev.value("c4") * ev.vd
    if ev.jacobian:
        ev.ds[..., ev.index["c4"]] = ev.vd


def _valve_rate(term: Term, ev: Evaluation) -> None:
    """n += c7 k(û; c_γ, c9, c8): the rate's dependence on the valve, thesis eq. (4.9), (4.10d-e);
    reads c1 (through û) from the valve's steady state."""
    c7, c8 = ev.value("c7"), ev.value("c8")
    uh, cg = ev.uh, ev.c_gamma
    ru = np.sqrt(uh * uh + cg * cg)
    k = ru - cg + ev.value("c9") + c8 * uh  # (4.10d), k(û; c_γ, c9, c8)
    ev.num = c7 * k
    if ev.jacobian:
        ev.dnum = ev.zeros()
        ev.dnum[..., ev.index["c1"]] = -c7 * (uh / ru + c8)
        ev.dnum[..., ev.index["c7"]] = k
        ev.dnum[..., ev.index["c8"]] = c7 * uh
        ev.dnum[..., ev.index["c9"]] = c7


def _volume_rate_rate(term: Term, ev: Evaluation) -> None:
    """n += c5 v̇: the volume rate in the rate, thesis eq. (4.10e)."""
    ev.num = ev.num + ev.value("c5") * ev.vd
    if ev.jacobian:
        ev.dnum[..., ev.index["c5"]] = ev.vd


def _chamber_volume(term: Term, ev: Evaluation) -> None:
    """d += c6 v: the chamber's volume 1 + c6 v in the rate's denominator, thesis eq. (4.10e)."""
    ev.den = 1.0 + ev.value("c6") * ev.v
    if ev.jacobian:
        ev.dden = ev.zeros()
        ev.dden[..., ev.index["c6"]] = ev.v


# ----------------------------------------------------------------------------- extra terms
def _split_step(term: Term, ev: Evaluation) -> None:
    """``valve_delay`` (the valve answers the command ``delay_s`` late) and ``sensor_lag`` (the
    tick-averaged pressure answers a fraction of a tick late, thesis §4.5: not a fault, fitted with
    the baseline so that only a delay beyond the sampling's own is a ``valve_delay``; with both, the
    reading answers the command their sum late). With D = delay / h = n + f, the valve holds u_{t-n-1} for the first f h
    of the step t -> t+1 and u_{t-n} for the rest: the model takes two exact steps (4.7), the exact
    solution of (4.6) for that piecewise-constant command. The model applies it; no part is added."""
    return None


def _chamber_leak(term: Term, ev: Evaluation) -> None:
    """Air escapes to the room: pdot += -leak Φ(p) / (1 + c6 v), a flow into a chamber of volume ∝
    1 + c6 v.

    ``extra: {shape: orifice}`` (what ``diagnose`` fits): Φ is the thin-plate outflow of an orifice
    to the room, thesis eq. (4.1), normalised to p where it is choked (:func:`orifice_outflow`), so
    the leak falls off steeply near the room pressure; it enters the step linearised at the step's
    start (α - β p with β = leak Φ'(p_t), α = -leak (Φ(p_t) - Φ'(p_t) p_t)). Without a shape (files
    written before it): Φ = p - P_r. The orifice is what a hole is: on the thin-plate leaks of two
    simulators it lowers the held-out error more than the linear form.
    """
    c = ev.value("leak")
    if term.extra.get("shape") == "orifice":
        phi, dphi, d2phi = orifice_outflow(ev.p, ev.room)
    else:
        phi, dphi, d2phi = ev.p - ev.room, np.ones_like(np.asarray(ev.p, float)), 0.0
    rest = phi - dphi * ev.p  # Φ(p) ≈ rest + Φ' p near the step's start
    beta, alpha = c * dphi / ev.den, -c * rest / ev.den
    dbeta = dalpha = None
    if ev.jacobian:
        dbeta = -beta[..., None] * ev.dden / ev.den[..., None]
        dbeta[..., ev.index["leak"]] += dphi / ev.den
        dalpha = -alpha[..., None] * ev.dden / ev.den[..., None]
        dalpha[..., ev.index["leak"]] -= rest / ev.den
    ev.add_flow(alpha, beta, dalpha, dbeta, c * d2phi * ev.p / ev.den, c * d2phi / ev.den)


#: Air's heat capacity ratio and the critical pressure ratio of thin-plate flow (thesis eq. 4.14);
#: above ``_X_LAMINAR`` (p_d/p_u) the flow is continued linearly to 0 (eq. 4.1's slope is infinite
#: at equal pressures).
_KAPPA = 1.4
_X_CRIT = (2.0 / (_KAPPA + 1.0)) ** (_KAPPA / (_KAPPA - 1.0))
_X_LAMINAR = 0.98


def _psi(x):
    """Ψ(x) of thesis eq. (4.1) (x = p_d / p_u) and its first two derivatives in x: constant when
    choked, subsonic above, linear in the laminar end."""
    e1, e2, c = 2.0 / _KAPPA, (_KAPPA + 1.0) / _KAPPA, 2.0 * _KAPPA / (_KAPPA - 1.0)
    xs = np.clip(x, _X_CRIT, _X_LAMINAR)
    w = np.sqrt(c * (xs**e1 - xs**e2))
    dw = c * (e1 * xs ** (e1 - 1.0) - e2 * xs ** (e2 - 1.0)) / (2.0 * w)
    d2w = (c * (e1 * (e1 - 1.0) * xs ** (e1 - 2.0) - e2 * (e2 - 1.0) * xs ** (e2 - 2.0)) - 2.0 * dw**2) / (2.0 * w)
    w_lam = np.sqrt(c * (_X_LAMINAR**e1 - _X_LAMINAR**e2))
    lam, choked = x > _X_LAMINAR, x < _X_CRIT
    psi = np.where(lam, w_lam * (1.0 - x) / (1.0 - _X_LAMINAR), w)
    dpsi = np.where(lam, -w_lam / (1.0 - _X_LAMINAR), np.where(choked, 0.0, dw))
    return psi, dpsi, np.where(lam | choked, 0.0, d2w)


_PSI_CHOKED = float(_psi(np.array(0.0))[0])


def orifice_outflow(p, room):
    """Φ(p) = p Ψ(P_r / p) / Ψ_choked, the thin-plate outflow of an orifice to the room (thesis eq.
    4.1) in pressure units, equal to p where it is choked and 0 at or below P_r, with dΦ/dp and
    d²Φ/dp²."""
    p = np.asarray(p, float)
    pp = np.maximum(p, room * (1.0 + 1e-9))
    x = room / pp
    psi, dpsi, d2psi = _psi(x)
    below = p <= room
    phi = np.where(below, 0.0, pp * psi / _PSI_CHOKED)
    dphi = np.where(below, 0.0, (psi - x * dpsi) / _PSI_CHOKED)
    return phi, dphi, np.where(below, 0.0, x * x * d2psi / (pp * _PSI_CHOKED))


def _supply_droop(term: Term, ev: Evaluation) -> None:
    """The supply sags while the valve draws from it; s loses f Δ, f = (1 + g)/2 the supply's share
    of the port flow (the part of s between P_r and P_c), Δ the sag the valve sees. Reads g
    (c1..c3) of the baseline and, for the flow shape, the rate's numerator n (c5, c7..c9).

    Two shapes of Δ, both in the pressure unit, chosen by ``extra: {shape: ...}``:

    - ``share`` (the default): Δ = droop where the supply port is open, a sag that lasts while
      flow is drawn, as through a supply line of high linear resistance that the valve's own
      through-flow keeps loaded (the project's simulator);
    - ``flow``: Δ = (P_c - p) x / (1 + x), x = droop f n / (c7 c_s · 1 V), the sag of a line
      resistance in series with the supply port, whose flow f n (P_c' - p) it carries (x is the line's
      resistance times the port's conductance): deep while a chamber fills, none once it is full.
      ``droop`` is the sag (small-sag limit) when a supply port opened one volt beyond c1 fills a
      chamber half a span below the supply. A restricted line (an orifice before a hose, the second
      generator) shows as this shape, not as the first; where the valve's own parameters (its rate
      asymmetry c8, the flow saturation) take the slower filling, it is not named;
    - ``orifice``: the same series form with x = droop w (c_s w), w = f n / (c7 c_s · 1 V) the
      flow shape's x per unit of droop: the sag of a restriction that is itself an orifice (a kinked
      tube, a clogged filter): through two orifices in series the pressure drop divides as the
      squares of their areas (flow ∝ area · √Δp, eq. 4.1 below choking), where linear resistances
      divide it as their conductances. c_s w is about 1 at one volt beyond c1, so ``droop`` keeps
      its meaning and unit.

    - ``hose``: the line resistance of ``flow`` feeds a hose of its own volume, whose pressure P_s
      is a state: the sag Δ = P_c - P_s obeys τ dΔ/dt = x (P_c - p) - (1 + x) Δ (x the flow
      shape's, τ = ``extra.tau_s`` the hose's volume over the line's conductance), the same
      first-order form as eq. (4.6), stepped by the same exact step (4.7)
      (:meth:`~diegocal.pneumatic.model.ChamberModel.line`). The chamber's step reads the sag
      averaged over the step (``ev.line``); its equilibrium is the flow shape's sag, which is the
      limit τ -> 0, and as τ grows the sag tends to a constant, the lasting sag of ``share``.

    A sag proportional to the flow drawn without the series form (P_c' = P_c - k f n (P_c - p)) was
    tried first on the project's simulator: it fitted worse than a pressure offset.
    """
    c = ev.value("droop")
    f = 0.5 * (1.0 + ev.g)
    at = ev.index["droop"]
    shape = term.extra.get("shape")
    if shape not in ("flow", "orifice", "hose"):
        ev.s = ev.s - c * f
        if ev.jacobian:
            ev.ds = ev.ds - 0.5 * c * ev.dg
            ev.ds[..., at] -= f
        return
    if shape == "hose" and ev.line is not None:  # the hose's sag over the step, an input
        ev.s = ev.s - f * ev.line
        if ev.jacobian:
            ev.ds = ev.ds - 0.5 * ev.line[..., None] * ev.dg
            if ev.dline is not None:
                ev.ds = ev.ds - f[..., None] * ev.dline
        return
    c7 = ev.value("c7")
    gap = ev.supply - ev.p
    w = f * ev.num / (c7 * ev.c_s)  # the port's conductance over the line's, per unit of droop
    power = 2.0 if shape == "orifice" else 1.0
    weight = (w * ev.c_s) ** (power - 1.0)  # orifice: the port's opening (about 1 at 1 V beyond c1)
    wp = w * weight  # x per unit of droop
    x = np.maximum(c * wp, 0.0)
    q = x / (1.0 + x)
    dq = np.where(c * wp > 0.0, 1.0 / (1.0 + x) ** 2, 0.0)
    sag = q * gap
    ev.s = ev.s - f * sag
    ev.s_p = f * q if ev.s_p is None else ev.s_p + f * q  # d s / d p
    if ev.jacobian:
        dw = (0.5 * ev.dg * ev.num[..., None] + f[..., None] * ev.dnum) / (c7 * ev.c_s)
        dw[..., ev.index["c7"]] -= w / c7
        dwp = (power * weight)[..., None] * dw
        ds = -(0.5 * sag)[..., None] * ev.dg - (f * dq * gap)[..., None] * (c * dwp)
        ds[..., at] -= f * dq * gap * wp
        ev.ds = ev.ds + ds


def hose_load(term: Term, ev: Evaluation):
    """x (N,) of a ``supply_droop``: the valve's supply-port conductance over the line's (the flow
    shape's x, droop f n / (c7 c_s · 1 V)), and d x / d x (N, P) (None unless ``ev.jacobian``);
    reads g and n of the baseline (an evaluation run up to the terms that read them)."""
    c, c7 = ev.value("droop"), ev.value("c7")
    f = 0.5 * (1.0 + ev.g)
    w = f * ev.num / (c7 * ev.c_s)
    x = np.maximum(c * w, 0.0)
    if not ev.jacobian:
        return x, None
    dw = (0.5 * ev.dg * ev.num[..., None] + f[..., None] * ev.dnum) / (c7 * ev.c_s)
    dw[..., ev.index["c7"]] -= w / c7
    dx = c * dw
    dx[..., ev.index["droop"]] += w
    return x, np.where((c * w > 0.0)[..., None], dx, 0.0)


def _pressure_offset(term: Term, ev: Evaluation) -> None:
    """The pressure sensor reads p + offset (its zero drifted): the model shifts the reading
    (:meth:`~diegocal.pneumatic.model.ChamberModel.step`); no part is added."""
    return None


def _flow_saturation(term: Term, ev: Evaluation) -> None:
    """The ports' flow saturates with the pressure difference: r' = r / (1 + sat |s - p| / c_s).

    Not a fault: the thin-plate flow of thesis eq. (4.1) is choked (independent of the downstream
    pressure) far from equilibrium and grows like a square root near it, while eq. (4.6) makes it
    proportional to s - p: far from s a chamber fills and empties at a rate less than proportional
    to the gap. ``diagnose`` fits it with the baseline (like ``sensor_lag``), so that this known
    limit of the 9-parameter model is not taken for structure that no term explains. It shapes the
    valve's rate only (an added flow such as a leak keeps its own), after the whole s is known.
    """
    k = ev.value("sat")
    gap = ev.s - ev.p
    a = np.abs(gap) / ev.c_s
    f = 1.0 / (1.0 + k * a)
    ev.factor = f
    sgn = np.sign(gap) / ev.c_s
    s_p = 0.0 if ev.s_p is None else ev.s_p
    ev.factor_p = -(f * f) * k * sgn * (s_p - 1.0)  # d f / d p
    if ev.jacobian:
        ev.dfactor = -((f * f) * k * sgn)[..., None] * ev.ds
        ev.dfactor[..., ev.index["sat"]] -= f * f * a


#: cause -> its part of the chamber model (every pneumatic cause of the registry).
PARTS: dict[str, Part] = {
    "valve_steady_state": Part(1, _valve_steady_state),
    "volume_rate_steady": Part(1, _volume_rate_steady),
    "valve_rate": Part(2, _valve_rate),
    "volume_rate_rate": Part(2, _volume_rate_rate),
    "chamber_volume": Part(3, _chamber_volume),
    "valve_delay": Part(0, _split_step, delay=True),
    "sensor_lag": Part(0, _split_step, delay=True),
    "supply_droop": Part(4, _supply_droop),
    "flow_saturation": Part(4.5, _flow_saturation),
    "chamber_leak": Part(5, _chamber_leak),
    "pressure_offset": Part(6, _pressure_offset),
}
#: The baseline terms in the order of eq. (4.10), and their parameters in Table 4.1's order.
BASELINE: tuple[str, ...] = causes_of("pneumatics", "baseline")
BASELINE_SPECS = (C1, C2, C3, C4, C5, C6, C7, C8, C9)
#: The causes a diagnosis may name (the registry's pneumatic terms).
CAUSES: tuple[str, ...] = causes_of("pneumatics", "term")


def part(term: Term) -> Part:
    """The chamber-model part of ``term``'s cause (one clear error for a cause of another domain)."""
    try:
        return PARTS[term.cause]
    except KeyError:
        raise InputFileError(f"{term.cause} is not a term of a valve-chamber model") from None


def specs_of(term: Term):
    """The registry's parameter specs (unit, bounds, start) of ``term``'s cause."""
    return registry_entry(term.cause).parameters


def baseline_terms(channel: str = "", values: dict | None = None) -> tuple[Term, ...]:
    """The five baseline terms of eq. (4.10) with ``values`` by name (default: Table 4.1's starts)."""
    values = values or {}
    out = []
    for cause in BASELINE:
        names = registry_entry(cause).parameter_names
        out.append(make_term(cause, channel, {n: values[n] for n in names if n in values}))
    return tuple(out)


def chamber_terms(terms) -> tuple[Term, ...]:
    """``terms`` as a tuple, each checked to be a valve-chamber term (:func:`part`)."""
    terms = tuple(terms)
    for t in terms:
        part(t)
    return terms
