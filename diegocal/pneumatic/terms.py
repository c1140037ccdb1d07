"""The terms of the valve-chamber model: thesis eq. (4.10) as baseline terms, plus extra terms.

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

Extra terms (``diagnose``'s vocabulary, DESIGN.md; channel = the chamber) keep the form (4.6), so
that the exact step (4.7) still applies:

- ``valve_delay`` (delay_s, s): the valve answers the command ``delay_s`` late: within a step the
  valve holds first the older command, then the newer one, and the model takes one exact step
  (4.7) per piece;
- ``chamber_leak`` (leak, 1/s): air escapes to the room, an added outflow
  ``-leak (p - P_r) / (1 + c6 v)`` (a flow into a chamber of volume ∝ 1 + c6 v);
- ``supply_droop`` (droop, pressure unit): the supply sags while the valve draws from it: the
  valve sees P_c - droop through its supply port, so s loses ``droop f`` with f = (1 + g)/2 the
  supply's share of the port flow (the part of s between P_r and P_c);
- ``pressure_offset`` (offset, pressure unit): the sensor reads p + offset; the model runs on the
  reading minus the offset;
- ``sensor_lag`` (lag_s, s; at most one tick): the tick-averaged pressure answers the command a
  fraction of a tick late (thesis §4.5); the form of ``valve_delay``, which it excludes;
- ``flow_saturation`` (sat, 1): the valve's rate r becomes r / (1 + sat |s - p| / c_s): the
  thin-plate flow (4.1) is choked far from equilibrium, less than proportional to s - p.

Folding the flows into (s, r): ``(s - p) r + α - β p = (s' - p) r'`` with r' = r + β and
s' = (s r + α) / r'.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from diegocal.errors import InputFileError
from diegocal.terms import Parameter, Term

#: The longest valve delay the model (and diagnose's grid) considers, s.
MAX_DELAY_S = 0.1
#: The longest lag of the tick-averaged sensors (one 10 ms tick, thesis §4.5), s.
MAX_SENSOR_LAG_S = 0.01


@dataclass(frozen=True)
class ParamSpec:
    """One free parameter: name, unit, bounds (Table 4.1 or ours, see ``note``), start value."""

    name: str
    unit: str
    lower: float
    upper: float
    start: float
    meaning: str
    note: str = ""

    def parameter(self, value: float | None = None, stderr: float = np.nan) -> Parameter:
        v = self.start if value is None else float(value)
        return Parameter(self.name, v, self.unit, self.lower, self.upper, stderr)


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
    factor of the valve's rate num/den, its derivative in p and in x (None: 1).
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
    s_p: np.ndarray | None = None
    factor: np.ndarray | None = None
    factor_p: np.ndarray | None = None
    dfactor: np.ndarray | None = None
    shape: tuple = field(default=())

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

    def add_flow(self, alpha, beta, dalpha=None, dbeta=None) -> None:
        """Add ``alpha - beta p`` to pdot (pu/s); derivatives (N, P) when ``jacobian``."""
        self.alpha = alpha if self.alpha is None else self.alpha + alpha
        self.beta = beta if self.beta is None else self.beta + beta
        if self.jacobian:
            self.dalpha = dalpha if self.dalpha is None else self.dalpha + dalpha
            self.dbeta = dbeta if self.dbeta is None else self.dbeta + dbeta


class ChamberTerm(Term):
    """A term of the chamber model: its parameters (``specs``) and what it adds (:meth:`add`).

    ``stage`` orders the terms in an evaluation: inputs (0), steady state (1), rate numerator (2),
    volume (3), terms that read the baseline's parts (4), flows (5), the sensor reading (6).
    """

    CAUSE: ClassVar[str] = ""
    specs: ClassVar[tuple[ParamSpec, ...]] = ()
    stage: ClassVar[float] = 1
    baseline: ClassVar[bool] = False

    def add(self, ev: Evaluation) -> None:  # pragma: no cover - every term overrides it
        raise NotImplementedError


# ----------------------------------------------------------------------------- baseline (Table 4.1)
#: Bounds from Table 4.1; c2 > 0 and c7 > 0 are ours: they fix the sign conventions (s increases
#: with u, the rate r is positive) that the thesis states in words ("r() > 0", §4.3) but does not
#: list in the table.
C1 = ParamSpec("c1", "V", 2.0, 8.0, 5.0, "valve-voltage origin (U_c + U_r)/2", "Table 4.1")
C2 = ParamSpec("c2", "1/V", 1e-3, np.inf, 1.0, "valve-voltage scale B", "ours: > 0")
C3 = ParamSpec("c3", "1/V^3", -1.0, np.inf, 0.0, "kink factor", "Table 4.1")
C4 = ParamSpec("c4", "pu s", -np.inf, np.inf, 0.0, "ds/dvdot", "")
C5 = ParamSpec("c5", "1", -np.inf, np.inf, 0.0, "dr/dvdot", "")
C6 = ParamSpec(
    "c6",
    "1",
    -0.98,
    0.98,
    0.0,
    "volume-sensor scale",
    "|c6| < 1 keeps 1 + c6 v' > 0 on the normalised travel v' in [-1, 1]",
)
C7 = ParamSpec("c7", "1/(s V)", 1e-6, np.inf, 10.0, "B of eq. (4.3): rate per volt", "ours: > 0")
C8 = ParamSpec("c8", "1", -1.0, 1.0, 0.0, "rate asymmetry", "Table 4.1")
C9 = ParamSpec("c9", "V", 1e-6, np.inf, 0.05, "leakage (L_c + L_r)/2", "Table 4.1: > 0")


class ValveSteadyState(ChamberTerm):
    """s += c_s g(c2 û + c3 û³), û = u - c1: the valve's steady state, thesis eq. (4.10a-c)."""

    CAUSE = "valve_steady_state"
    specs = (C1, C2, C3)
    stage = 1
    baseline = True

    def add(self, ev: Evaluation) -> None:
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


class VolumeRateSteady(ChamberTerm):
    """s += c4 v̇: the volume rate drives the steady state, thesis eq. (4.10c)."""

    CAUSE = "volume_rate_steady"
    specs = (C4,)
    stage = 1
    baseline = True

    def add(self, ev: Evaluation) -> None:
        ev.s = ev.s + ev.value("c4") * ev.vd
        if ev.jacobian:
            ev.ds[..., ev.index["c4"]] = ev.vd


class ValveRate(ChamberTerm):
    """n += c7 k(û; c_γ, c9, c8): the rate's dependence on the valve, thesis eq. (4.9), (4.10d-e).

    Reads c1 (through û) from :class:`ValveSteadyState`.
    """

    CAUSE = "valve_rate"
    specs = (C7, C8, C9)
    stage = 2
    baseline = True

    def add(self, ev: Evaluation) -> None:
        c1, c7, c8, c9 = (ev.value(n) for n in ("c1", "c7", "c8", "c9"))
        uh, cg = ev.uh, ev.c_gamma
        ru = np.sqrt(uh * uh + cg * cg)
        k = ru - cg + c9 + c8 * uh  # (4.10d), k(û; c_γ, c9, c8)
        ev.num = c7 * k
        if ev.jacobian:
            ev.dnum = ev.zeros()
            ev.dnum[..., ev.index["c1"]] = -c7 * (uh / ru + c8)
            ev.dnum[..., ev.index["c7"]] = k
            ev.dnum[..., ev.index["c8"]] = c7 * uh
            ev.dnum[..., ev.index["c9"]] = c7


class VolumeRateRate(ChamberTerm):
    """n += c5 v̇: the volume rate in the rate, thesis eq. (4.10e)."""

    CAUSE = "volume_rate_rate"
    specs = (C5,)
    stage = 2
    baseline = True

    def add(self, ev: Evaluation) -> None:
        ev.num = ev.num + ev.value("c5") * ev.vd
        if ev.jacobian:
            ev.dnum[..., ev.index["c5"]] = ev.vd


class ChamberVolume(ChamberTerm):
    """d += c6 v: the chamber's volume 1 + c6 v in the rate's denominator, thesis eq. (4.10e)."""

    CAUSE = "chamber_volume"
    specs = (C6,)
    stage = 3
    baseline = True

    def add(self, ev: Evaluation) -> None:
        ev.den = 1.0 + ev.value("c6") * ev.v
        if ev.jacobian:
            ev.dden = ev.zeros()
            ev.dden[..., ev.index["c6"]] = ev.v


#: The baseline terms in the order of eq. (4.10), and their parameters in Table 4.1's order.
BASELINE: tuple[type[ChamberTerm], ...] = (
    ValveSteadyState,
    VolumeRateSteady,
    ValveRate,
    VolumeRateRate,
    ChamberVolume,
)
BASELINE_SPECS: tuple[ParamSpec, ...] = (C1, C2, C3, C4, C5, C6, C7, C8, C9)


def baseline_terms(channel: str = "", values: dict | None = None) -> tuple[ChamberTerm, ...]:
    """The five baseline terms of eq. (4.10) with ``values`` by name (default: Table 4.1's starts)."""
    values = values or {}
    return tuple(
        cls(cls.CAUSE, channel, tuple(s.parameter(values.get(s.name)) for s in cls.specs))
        for cls in BASELINE
    )


# ----------------------------------------------------------------------------- extra terms
class ValveDelay(ChamberTerm):
    """The valve answers the command ``delay_s`` late.

    With D = delay_s / h = n + f (n whole samples, 0 <= f < 1), the valve holds u_{t-n-1} for the
    first f h of the step t -> t+1 and u_{t-n} for the rest: the model takes two exact steps (4.7),
    over f h and (1 - f) h (the exact solution of (4.6) for that piecewise-constant command).
    :meth:`~diegocal.pneumatic.model.ChamberModel.step` applies it; the term adds no part.
    """

    CAUSE = "valve_delay"
    specs = (ParamSpec("delay_s", "s", 0.0, MAX_DELAY_S, 0.0, "valve delay"),)
    stage = 0

    def add(self, ev: Evaluation) -> None:  # the model splits the step (see the docstring)
        return None


class SensorLag(ValveDelay):
    """The measured pressure lags the command by a fraction of a sample, û = u(t - lag_s) - c1.

    Not a fault: thesis §4.5 averages every sensor over each 10 ms tick (200 samples at 20 kHz),
    so the pressure read at t is the mean over the last tick and answers a command change about
    half a tick late. The 9-parameter model's next step cannot express that; ``diagnose`` fits it
    with the baseline (at most :data:`MAX_SENSOR_LAG_S`), so that only a delay beyond the
    sampling's own is a ``valve_delay``. Same form as :class:`ValveDelay` (the two exclude each
    other: a valve delay's value includes the sensor's lag).
    """

    CAUSE = "sensor_lag"
    specs = (ParamSpec("lag_s", "s", 0.0, MAX_SENSOR_LAG_S, 0.0, "lag of the tick-averaged sensors"),)


class ChamberLeak(ChamberTerm):
    """Air escapes to the room: pdot += -leak (p - P_r) / (1 + c6 v)."""

    CAUSE = "chamber_leak"
    specs = (ParamSpec("leak", "1/s", 0.0, np.inf, 0.0, "leak rate to the room"),)
    stage = 5

    def add(self, ev: Evaluation) -> None:
        c = ev.value("leak")
        beta = c / ev.den
        dbeta = dalpha = None
        if ev.jacobian:
            dbeta = -beta[..., None] * ev.dden / ev.den[..., None]
            dbeta[..., ev.index["leak"]] += 1.0 / ev.den
            dalpha = ev.room * dbeta
        ev.add_flow(ev.room * beta, beta, dalpha, dbeta)


class SupplyDroop(ChamberTerm):
    """The supply sags while the valve draws from it: the valve sees P_c - droop, so
    s = f (P_c - droop) + (1 - f) P_r loses ``droop f``, f = (1 + g)/2 the supply's share of the
    port flow (the part of s between P_r and P_c). Reads g (c1..c3) of the baseline.

    A sag is felt only through the supply port, in proportion to its share: where the valve is
    open to the room (f ≈ 0) nothing changes; where it is open to the supply, the chamber settles
    ``droop`` below the supply pressure of sensors.yaml. (A sag proportional to the rate of flow
    drawn, P_c' = P_c - k f n (P_c' - p), was tried first: on the simulator's supply line, whose
    choked flow sags the supply by tens of kPa while a chamber fills, it fitted worse than a
    pressure offset, which this shape does not.)
    """

    CAUSE = "supply_droop"
    specs = (ParamSpec("droop", "pu", 0.0, np.inf, 0.0, "supply sag while the valve draws from it"),)
    stage = 4

    def add(self, ev: Evaluation) -> None:
        c = ev.value("droop")
        f = 0.5 * (1.0 + ev.g)
        ev.s = ev.s - c * f
        if ev.jacobian:
            ev.ds = ev.ds - 0.5 * c * ev.dg
            ev.ds[..., ev.index["droop"]] -= f


class PressureOffset(ChamberTerm):
    """The pressure sensor reads p + offset (its zero drifted). Applied by the model to the reading."""

    CAUSE = "pressure_offset"
    specs = (ParamSpec("offset", "pu", -np.inf, np.inf, 0.0, "pressure-sensor offset"),)
    stage = 6

    def add(self, ev: Evaluation) -> None:  # the model shifts the reading (see ChamberModel.step)
        return None


class FlowSaturation(ChamberTerm):
    """The ports' flow saturates with the pressure difference: r' = r / (1 + sat |s - p| / c_s).

    Not a fault: the thin-plate flow of thesis eq. (4.1) is choked (independent of the downstream
    pressure) far from equilibrium and grows like a square root near it, while eq. (4.6) makes it
    proportional to s - p: far from s a chamber fills and empties at a rate less than proportional
    to the gap. ``diagnose`` fits it with the baseline (like ``sensor_lag``), so that this known
    limit of the 9-parameter model is not taken for structure that no term explains. It shapes the
    valve's rate only (an added flow such as a leak keeps its own), after the whole s is known.
    """

    CAUSE = "flow_saturation"
    specs = (ParamSpec("sat", "1", 0.0, 20.0, 0.0, "flow saturation per half-span c_s"),)
    stage = 4.5

    def add(self, ev: Evaluation) -> None:
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


#: Extra terms by cause: diagnose's vocabulary (DESIGN.md), :data:`CAUSES`; ``sensor_lag``, ``flow_saturation``.
EXTRA: dict[str, type[ChamberTerm]] = {
    "valve_delay": ValveDelay,
    "chamber_leak": ChamberLeak,
    "supply_droop": SupplyDroop,
    "pressure_offset": PressureOffset,
    "sensor_lag": SensorLag,
    "flow_saturation": FlowSaturation,
}
CAUSES: tuple[str, ...] = ("valve_delay", "chamber_leak", "supply_droop", "pressure_offset")


def make_term(cause: str, chamber: str, values: dict | None = None, stderr: dict | None = None,
              extra: dict | None = None) -> ChamberTerm:
    """An extra term of ``cause`` on ``chamber`` with parameter ``values`` by name (default: start)."""
    if cause not in EXTRA:
        raise InputFileError(f"unknown pneumatic term {cause!r}; known: {', '.join(CAUSES)}")
    cls = EXTRA[cause]
    values, stderr = values or {}, stderr or {}
    params = tuple(
        s.parameter(values.get(s.name), float(stderr.get(s.name, np.nan))) for s in cls.specs
    )
    return cls(cls.CAUSE, chamber, params, None, dict(extra or {}))


def as_chamber_term(term: Term) -> ChamberTerm:
    """A generic :class:`~diegocal.terms.Term` (from YAML or diagnose) as the chamber term of its
    cause, keeping its values and standard errors by name (bounds and units from the specs)."""
    if isinstance(term, ChamberTerm):
        return term
    vals = {p.name: p.value for p in term.parameters}
    se = {p.name: p.stderr for p in term.parameters}
    return make_term(term.cause, term.channel, vals, se, term.extra)


def term_from_dict(d: dict, where: str = "term") -> ChamberTerm:
    """An extra term from its YAML mapping (``Term.to_dict``)."""
    fields = Term.fields_from_dict(d, where)
    if fields["cause"] not in EXTRA:
        raise InputFileError(f"{where}: unknown pneumatic term {fields['cause']!r}; known: {', '.join(CAUSES)}")
    return as_chamber_term(Term(**fields))
