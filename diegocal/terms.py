"""Terms: the parts every model is built from, and what ``diagnose`` adds to a model.

A model of any domain is its *baseline terms* plus any *extra terms*. A term is

- a **cause** of the registry (:mod:`diegocal.causes`: ``pot_transfer``, ``coulomb_friction``,
  ``valve_delay``, ...),
- the **channel** it acts on (a joint, pot, marker, chamber, link, or ``markers`` for the mocap clock),
- an optional **region** where it applies (``q.joint3`` in [1.9, 2.3] rad; ``time`` from 31 s),
- named, bounded **parameters** with units and standard errors (lmfit's ``Parameter``), packed
  into a vector only at the optimiser's door,
- ``extra``: non-numeric facts (a partner channel, a ratio, the frames of a fault).

How a term changes its domain's model is the domain's behaviour (:mod:`diegocal.stac.terms`,
:mod:`diegocal.sgp.terms`, :mod:`diegocal.pneumatic.terms`), looked up by cause. This module
fixes the data and its one YAML form, used by every file diegocal writes::

    {cause, channel, region: {variable, low, high} | null,
     parameters: {name: {value, stderr, unit}}, extra: {...}}

Files of layout 1 spelt the standard error ``std``; :func:`term_from_dict` reads both.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from diegocal.causes import CAUSES, slide_unit
from diegocal.causes import cause as registry_entry
from diegocal.errors import InputFileError, UnknownNameError
from diegocal.io.files import to_plain

#: The one spelling of a standard error in every file (layout 1 also wrote ``std`` and ``_se``).
STDERR = "stderr"
#: Estimates that correlate at least this much are written next to each other (a parameter's
#: ``correlated: {other: ρ}``, calib.yaml and pneumatic.yaml).
CORRELATED = 0.9


@dataclass(frozen=True)
class Parameter:
    """One named, bounded parameter: value, unit, bounds and standard error (NaN: unknown)."""

    name: str
    value: float = 0.0
    unit: str = ""
    lower: float = -math.inf
    upper: float = math.inf
    stderr: float = math.nan

    def to_dict(self) -> dict:
        return {"value": _plain(self.value), STDERR: _plain(self.stderr), "unit": self.unit}


def parameter_dict(name: str, value, stderr=math.nan, unit: str = "") -> dict:
    """``{name: {value, stderr, unit}}``'s inner mapping for a value that is not a term's."""
    return Parameter(name, float(value), unit, stderr=float(stderr)).to_dict()


def read_parameter(name: str, d, where: str = "parameter") -> Parameter:
    """A :class:`Parameter` from its YAML form: ``{value, stderr, unit}`` (layout 1: ``std``) or a bare number."""
    if isinstance(d, dict):
        se = d.get(STDERR, d.get("std"))
        try:
            value = d.get("value", 0.0)  # null: not identified
            return Parameter(str(name), math.nan if value is None else float(value), str(d.get("unit") or ""),
                             stderr=math.nan if se is None else float(se))
        except (TypeError, ValueError):
            raise InputFileError(f"{where} {name!r}: value and stderr must be numbers, got {d!r}") from None
    try:
        return Parameter(str(name), float(d))
    except (TypeError, ValueError):
        raise InputFileError(f"{where} {name!r}: expected a number or {{value, stderr, unit}}, got {d!r}") from None


@dataclass(frozen=True)
class Region:
    """Where a term acts: ``low <= variable <= high`` (``variable``: ``q.<joint>``, ``time``, ...)."""

    variable: str
    low: float
    high: float

    def contains(self, x) -> np.ndarray:
        x = np.asarray(x, float)
        return (x >= self.low) & (x <= self.high)

    def to_dict(self) -> dict:
        return {"variable": self.variable, "low": float(self.low), "high": float(self.high)}

    @classmethod
    def from_dict(cls, d: dict | None) -> Region | None:
        if not d:
            return None
        try:
            return cls(str(d["variable"]), float(d["low"]), float(d["high"]))
        except (KeyError, TypeError, ValueError):
            raise InputFileError(f"a term's region must be {{variable, low, high}}, got {d!r}") from None


@dataclass(frozen=True)
class Term:
    """A cause on a channel, with its named parameters (see the module docstring)."""

    cause: str
    channel: str
    parameters: tuple[Parameter, ...] = ()
    region: Region | None = None
    extra: dict = field(default_factory=dict)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.parameters)

    @property
    def values(self) -> np.ndarray:
        """Parameter values packed in order (the optimiser's door)."""
        return np.array([p.value for p in self.parameters], dtype=float)

    @property
    def stderrs(self) -> np.ndarray:
        return np.array([p.stderr for p in self.parameters], dtype=float)

    def value(self, name: str) -> float:
        for p in self.parameters:
            if p.name == name:
                return float(p.value)
        raise KeyError(f"term {self.cause}:{self.channel} has no parameter {name!r} (has {', '.join(self.names)})")

    def with_values(self, values, stderr=None) -> Term:
        """The same term with new values (and standard errors) in parameter order."""
        values = np.asarray(values, dtype=float).ravel()
        if values.size != len(self.parameters):
            raise ValueError(f"term {self.label}: expected {len(self.parameters)} values, got {values.size}")
        se = np.full(values.size, math.nan) if stderr is None else np.asarray(stderr, float).ravel()
        params = tuple(
            replace(p, value=float(v), stderr=float(s)) for p, v, s in zip(self.parameters, values, se, strict=True)
        )
        return replace(self, parameters=params)

    @property
    def linear(self) -> tuple[Parameter, ...]:
        """The parameters that are a column's coefficient (not a shape parameter, :mod:`diegocal.causes`)."""
        shape = _shape_names(self.cause)
        return tuple(p for p in self.parameters if p.name not in shape)

    def with_linear_values(self, values, stderr=None) -> Term:
        """The same term with new values (and standard errors) of its linear parameters, in order;
        its shape parameters kept."""
        values = np.asarray(values, dtype=float).ravel()
        lin = self.linear
        if values.size != len(lin):
            raise ValueError(f"term {self.label}: expected {len(lin)} linear values, got {values.size}")
        se = np.full(values.size, math.nan) if stderr is None else np.asarray(stderr, float).ravel()
        new = {p.name: replace(p, value=float(v), stderr=float(e)) for p, v, e in zip(lin, values, se, strict=True)}
        return replace(self, parameters=tuple(new.get(p.name, p) for p in self.parameters))

    @property
    def label(self) -> str:
        """``cause:channel`` (with the region when there is one), for messages and tables."""
        text = f"{self.cause}:{self.channel}"
        if self.region is not None:
            text += f" [{self.region.variable} {self.region.low:.3g}..{self.region.high:.3g}]"
        return text

    def to_dict(self) -> dict:
        out = {
            "cause": self.cause,
            "channel": self.channel,
            "region": None if self.region is None else self.region.to_dict(),
            "parameters": {p.name: p.to_dict() for p in self.parameters},
        }
        if self.extra:
            out["extra"] = to_plain(self.extra)
        return out


def _shape_names(cause: str) -> frozenset:
    """Names of a cause's shape parameters (none for a cause the registry does not know)."""
    entry = CAUSES.get(cause)
    return frozenset(p.name for p in entry.parameters if p.shape) if entry else frozenset()


def make_term(cause: str, channel: str, values=None, region: Region | None = None, extra: dict | None = None,
              stderr=None) -> Term:
    """A term of ``cause`` on ``channel`` with the registry's parameters (:mod:`diegocal.causes`).

    ``values`` and ``stderr``: a sequence in the registry's order, or a mapping by name (missing
    names take the registry's start value and a NaN standard error); None: start values. A cause
    whose parameters the model names (``rigid_body``) takes them from a mapping. A region or extra
    fact the cause requires must be given."""
    entry = registry_entry(cause)
    if entry.region == "required" and region is None:
        raise InputFileError(f"{cause}:{channel} needs a region")
    if entry.region == "none" and region is not None:
        raise InputFileError(f"{cause}:{channel} takes no region, got {region}")
    missing = [k for k in entry.extra if k not in (extra or {})]
    if missing and entry.role != "fault":  # a fault's facts are filled in once it is found
        raise InputFileError(f"{cause}:{channel} needs extra {{{', '.join(missing)}}}")
    if entry.named_by_model:
        vals = dict(values or {})
        ses = dict(stderr or {})
        params = tuple(Parameter(str(n), float(v), stderr=float(ses.get(n, math.nan))) for n, v in vals.items())
    else:
        specs = entry.parameters
        vals = _by_position(values, specs, "values", cause)
        ses = _by_position(stderr, specs, "stderr", cause, math.nan)
        params = tuple(
            Parameter(s.name, v, s.unit, s.lower, s.upper, e) for s, v, e in zip(specs, vals, ses, strict=True)
        )
    return Term(cause, str(channel), params, region, dict(extra or {}))


def _by_position(given, specs, what: str, cause: str, default=None) -> list[float]:
    """Values for ``specs`` from a sequence in order or a mapping by name (``default``: the start)."""
    if given is None:
        return [s.start if default is None else default for s in specs]
    if isinstance(given, dict):
        unknown = [k for k in given if k not in {s.name for s in specs}]
        if unknown:
            raise InputFileError(f"{cause} has no parameter {unknown[0]!r} (has {', '.join(s.name for s in specs)})")
        return [float(given.get(s.name, s.start if default is None else default)) for s in specs]
    arr = np.asarray(given, float).ravel()
    if arr.size != len(specs):
        raise InputFileError(f"{cause}: expected {len(specs)} {what}, got {arr.size}")
    return [float(v) for v in arr]


def term_from_dict(d: dict, where: str = "term", domain: str | None = None) -> Term:
    """A term from its YAML mapping (:meth:`Term.to_dict`, or layout 1's ``std``), checked against
    the registry: a known cause (of ``domain`` when given) with exactly its parameters."""
    if not isinstance(d, dict) or "cause" not in d or "channel" not in d:
        raise InputFileError(f"{where}: a term needs 'cause' and 'channel', got {d!r}")
    try:
        entry = registry_entry(str(d["cause"]))
    except UnknownNameError as exc:
        raise InputFileError(f"{where}: {exc}") from None
    if domain is not None and entry.domain not in (domain, "any"):
        raise InputFileError(f"{where}: {entry.id} is a {entry.domain} cause, not a {domain} one")
    raw = d.get("parameters") or {}
    if not isinstance(raw, dict):
        raise InputFileError(f"{where}: 'parameters' must be a mapping of name -> {{value, stderr, unit}}")
    given = [read_parameter(n, p, f"{where}: parameter") for n, p in raw.items()]
    if not entry.named_by_model:
        names, got = entry.parameter_names, tuple(p.name for p in given)
        earlier = {s.name: s.earlier for s in entry.parameters if s.earlier is not None and s.name not in got}
        if got != tuple(n for n in names if n not in earlier):
            raise InputFileError(f"{where}: {entry.id} has parameters {list(names)}, got {list(got)}")
        given += [Parameter(n, v) for n, v in earlier.items()]  # a file written before the parameter
    values = {p.name: p.value for p in given}
    stderr = {p.name: p.stderr for p in given}
    term = make_term(entry.id, d["channel"], values, Region.from_dict(d.get("region")), dict(d.get("extra") or {}),
                     stderr)
    units = {p.name: p.unit for p in given if p.unit}  # a channel's own unit (a linear pot's V/m) wins
    return replace(term, parameters=tuple(replace(p, unit=units.get(p.name, p.unit)) for p in term.parameters))


def _plain(v) -> float | None:
    v = float(v)
    return None if not math.isfinite(v) else v


def correlated_pairs(cov, labels, threshold: float = CORRELATED) -> list[tuple[str, str, float]]:
    """(label a, label b, ρ) of the estimates whose correlation (from the covariance ``cov``,
    labelled ``labels``) is at least ``threshold`` in size; a NaN or zero variance: none."""
    cov = np.asarray(cov, float)
    sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    out = []
    for i, j in zip(*np.triu_indices(len(labels), 1), strict=True):
        if sd[i] > 0 and sd[j] > 0:
            rho = cov[i, j] / (sd[i] * sd[j])
            if abs(rho) >= threshold:  # (NaN: never)
                out.append((labels[i], labels[j], float(rho)))
    return out


def write_correlated(terms: list, pairs) -> None:
    """Each parameter of the term mappings ``terms`` (:meth:`Term.to_dict`) that trades off gets
    ``correlated: {CHANNEL.NAME: ρ}`` (an added key: readers that do not know it read the value as
    before); ``pairs``: (label, label, ρ) with labels CHANNEL.NAME."""
    by: dict = {}
    for a, b, rho in pairs:
        by.setdefault(a, {})[b] = round(float(rho), 3)
        by.setdefault(b, {})[a] = round(float(rho), 3)
    for d in terms:
        for name, p in (d.get("parameters") or {}).items():
            if f"{d['channel']}.{name}" in by:
                p["correlated"] = by[f"{d['channel']}.{name}"]


def in_slide_units(term: Term) -> Term:
    """``term`` with its parameters' units as they read on a prismatic joint (N, m, kg:
    :func:`diegocal.causes.slide_unit`; the registry's are a revolute joint's)."""
    return replace(term, parameters=tuple(replace(p, unit=slide_unit(p.unit)) for p in term.parameters))
