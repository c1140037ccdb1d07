"""Terms: the parts every model family is built from, and what ``diagnose`` adds to a model.

A model of any domain is its *baseline terms* plus any *extra terms*. A term is

- a **cause** from the diagnosis vocabulary (DESIGN.md, "Diagnosis output"; ``viscous_friction``,
  ``sensor_nonlinearity``, ``chamber_leak``, ...) or a baseline part's own name,
- the **channel** it acts on (a joint, pot, marker, chamber, or ``markers`` for the mocap clock),
- an optional **region** where it applies (``q.joint3`` in [1.9, 2.3] rad; ``time`` from 31 s),
- named, bounded **parameters** with units and standard errors (lmfit's ``Parameter``), packed
  into a vector only at the optimiser's door.

How a term contributes to a model's output (regressor columns, a Jacobian, a transform of the
readings) is the domain's business: :mod:`diegocal.sgp.terms`, :mod:`diegocal.pneumatic.terms`
and :mod:`diegocal.stac.terms` subclass :class:`Term`. This module only fixes the vocabulary of
the data and its YAML form, ``{cause, channel, region, parameters: {name: {value, std, unit}}}``,
which diagnosis.yaml and every fitted-model bundle use.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from diegocal.errors import InputFileError


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
        out = {"value": float(self.value), "std": _plain(self.stderr)}
        if self.unit:
            out["unit"] = self.unit
        return out


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
    """A cause on a channel, with its named parameters (see the module docstring).

    Subclasses add how the term enters their domain's model; this base class carries the data
    and the YAML form shared by every domain.
    """

    cause: str
    channel: str
    parameters: tuple[Parameter, ...] = ()
    region: Region | None = None
    extra: dict = field(default_factory=dict)  # non-numeric facts (a swapped partner, frames)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.parameters)

    @property
    def values(self) -> np.ndarray:
        """Parameter values packed in order (the optimiser's door)."""
        return np.array([p.value for p in self.parameters], dtype=float)

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
            out["extra"] = _plain_tree(self.extra)
        return out

    @staticmethod
    def fields_from_dict(d: dict, where: str = "term") -> dict:
        """The keyword arguments of a Term (any subclass) from its YAML mapping."""
        if not isinstance(d, dict) or "cause" not in d or "channel" not in d:
            raise InputFileError(f"{where}: a term needs 'cause' and 'channel', got {d!r}")
        params = []
        for name, p in (d.get("parameters") or {}).items():
            if isinstance(p, dict):
                params.append(
                    Parameter(
                        str(name),
                        float(p.get("value", 0.0)),
                        str(p.get("unit", "")),
                        stderr=math.nan if p.get("std") is None else float(p["std"]),
                    )
                )
            else:
                params.append(Parameter(str(name), float(p)))
        return {
            "cause": str(d["cause"]),
            "channel": str(d["channel"]),
            "parameters": tuple(params),
            "region": Region.from_dict(d.get("region")),
            "extra": dict(d.get("extra") or {}),
        }


def _plain(v) -> float | None:
    v = float(v)
    return None if not math.isfinite(v) else v


def _plain_tree(obj):
    if isinstance(obj, dict):
        return {str(k): _plain_tree(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_plain_tree(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _plain_tree(obj.tolist())
    if isinstance(obj, np.generic):
        return obj.item()
    return obj
