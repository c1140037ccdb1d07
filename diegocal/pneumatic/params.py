"""Named, bounded parameters of the 9-parameter valve-chamber model (thesis §4.4, Table 4.1).

Parameters are named and carry units, bounds and standard errors (lmfit's ``Parameter``); they
are packed into a vector only at the optimiser's door (:meth:`ChamberParams.vector`,
:meth:`ChamberParams.from_vector`). ``v`` is the volume-sensor reading in its own unit
(normalised, see :class:`ChamberParams`) and ``u`` the valve voltage in V; pressure is in the
pressure stream's unit ("pu": kPa for the bundled robots).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from diegocal.causes import ParamSpec
from diegocal.errors import InputFileError
from diegocal.pneumatic.terms import BASELINE_SPECS, baseline_terms, chamber_terms
from diegocal.terms import term_from_dict

#: c_gamma, the voltage range of the leaky regime, fixed globally by the thesis (§4.4), V.
C_GAMMA = 0.1


#: The free parameters c1..c9 in order (Table 4.1; bounds, units and the notes on our own
#: bounds are in :mod:`diegocal.pneumatic.terms`, where each baseline term names its own).
SPECS: tuple[ParamSpec, ...] = BASELINE_SPECS
NAMES: tuple[str, ...] = tuple(s.name for s in SPECS)
N_PARAMS = len(SPECS)


def lower_bounds() -> np.ndarray:
    return np.array([s.lower for s in SPECS])


def upper_bounds() -> np.ndarray:
    return np.array([s.upper for s in SPECS])


def start_vector() -> np.ndarray:
    return np.array([s.start for s in SPECS])


@dataclass(frozen=True)
class ChamberParams:
    """The model of one valve-chamber system: c1..c9 plus the fixed c_b, c_s, c_gamma (thesis §4.4).

    Attributes
    ----------
    values : dict name -> float, the nine free parameters
    c_b, c_s : pressure-sensor bias (P_c + P_r)/2 and scale (P_c - P_r)/2, in pressure units
    c_gamma : leaky-regime voltage range, V (0.1 in the thesis)
    stderr : dict name -> float, standard errors (NaN where unknown)
    v_ref, v_scale : the model's volume coordinate is (v - v_ref) / v_scale (see below)
    terms : extra terms of the model (:mod:`diegocal.pneumatic.terms`: valve_delay, chamber_leak,
        supply_droop, pressure_offset) with their fitted values and standard errors

    Volume coordinate. Eq. (4.10e) divides by ``1 + c6 v``: the "1" is the volume at v = 0 in
    units of the sensor's bias (§4.4). With a raw pot reading, v = 0 may lie far outside the
    travel (or where the extrapolated volume is negative); then the best c6 is infinite and
    (c5, c6, c7) slide along their multiplicative invariance. We therefore feed the model the
    reading centred and scaled on the fitting data's range, v' = (v - v_ref) / v_scale in
    [-1, 1], where the volume is positive by construction, so |c6| < 1 is the physical range;
    vdot is scaled alike. This is a fixed affine change of the sensor unit, not a new parameter.
    """

    values: dict
    c_b: float
    c_s: float
    c_gamma: float = C_GAMMA
    stderr: dict = field(default_factory=dict)
    v_ref: float = 0.0
    v_scale: float = 1.0
    terms: tuple = ()

    def volume_coordinate(self, v, vd):
        """(v', v̇') = ((v - v_ref) / v_scale, v̇ / v_scale): the model's volume inputs."""
        return (np.asarray(v) - self.v_ref) / self.v_scale, np.asarray(vd) / self.v_scale

    @classmethod
    def nominal(cls, supply: float, room: float, **values) -> ChamberParams:
        """Start values of Table 4.1's parameters; c_b, c_s from the supply and room pressures."""
        vals = {s.name: s.start for s in SPECS}
        vals.update({k: float(v) for k, v in values.items()})
        return cls(vals, c_b=0.5 * (supply + room), c_s=0.5 * (supply - room))

    @property
    def supply(self) -> float:
        return self.c_b + self.c_s

    @property
    def room(self) -> float:
        return self.c_b - self.c_s

    def vector(self) -> np.ndarray:
        """The nine free parameters packed in the order of :data:`NAMES` (the optimiser's door)."""
        return np.array([float(self.values[n]) for n in NAMES])

    def names(self) -> tuple[str, ...]:
        """The names of :meth:`full_vector`'s entries: c1..c9, then the extra terms' parameters."""
        return NAMES + tuple(p.name for t in self.terms for p in t.parameters)

    def full_vector(self) -> np.ndarray:
        """c1..c9 then the extra terms' parameters, in the order of the model's ``names``."""
        return np.concatenate([self.vector(), *[t.values for t in self.terms]])

    def from_vector(self, x, stderr=None) -> ChamberParams:
        """New values (and standard errors) for c1..c9, or for c1..c9 and every extra term."""
        x = np.asarray(x, float)
        se_all = None if stderr is None else np.asarray(stderr, float)
        n = len(NAMES)
        if x.size not in (n, self.full_vector().size):
            raise ValueError(f"expected {n} or {self.full_vector().size} values, got {x.size}")
        vals = {k: float(v) for k, v in zip(NAMES, x[:n], strict=True)}
        se = {} if se_all is None else {k: float(v) for k, v in zip(NAMES, se_all[:n], strict=True)}
        terms = self.terms
        if x.size > n:
            terms, k = [], n
            for t in self.terms:
                m = len(t.parameters)
                terms.append(t.with_values(x[k : k + m], None if se_all is None else se_all[k : k + m]))
                k += m
            terms = tuple(terms)
        return replace(self, values=vals, stderr=se, terms=terms)

    def with_terms(self, terms) -> ChamberParams:
        """The same chamber with these extra terms (checked to be chamber terms)."""
        return replace(self, terms=chamber_terms(terms))

    def baseline_terms(self, channel: str = "") -> tuple:
        """c1..c9 as the five baseline terms of eq. (4.10), with values and standard errors."""
        se = {n: float(self.stderr.get(n, np.nan)) for n in NAMES}
        terms = baseline_terms(channel, self.values)
        return tuple(t.with_values(t.values, [se[n] for n in t.names]) for t in terms)

    def to_dict(self, channel: str = "") -> dict:
        """pneumatic.yaml's chamber entry (layout 2): the baseline terms, the extra terms, and the
        fixed constants c_b, c_s (pressure unit), c_gamma (V), v_ref, v_scale (volume sensor unit)."""
        out = {
            "baseline": [t.to_dict() for t in self.baseline_terms(channel)],
            "c_b": float(self.c_b),
            "c_s": float(self.c_s),
            "c_gamma": float(self.c_gamma),
            "v_ref": float(self.v_ref),
            "v_scale": float(self.v_scale),
        }
        if self.terms:
            out["terms"] = [t.to_dict() for t in self.terms]
        return out

    @classmethod
    def from_dict(cls, raw: dict, where: str = "chamber") -> ChamberParams:
        """A chamber from its pneumatic.yaml entry: layout 2 (``baseline`` terms) or layout 1
        (``c1``..``c9`` as numbers and ``stderr: {c1..c9}``)."""
        if not isinstance(raw, dict):
            raise InputFileError(f"{where}: expected a mapping with the baseline terms and c_b, c_s")
        missing = [k for k in ("c_b", "c_s") if k not in raw]
        if missing:
            raise InputFileError(f"{where}: missing {', '.join(missing)}")
        try:
            vals, se = _baseline_values(raw, where)
            extra = raw.get("terms") or []
            if not isinstance(extra, list):
                raise InputFileError(f"{where}: 'terms' must be a list of terms")
            terms = tuple(term_from_dict(t, f"{where}: term {i + 1}", "pneumatics") for i, t in enumerate(extra))
            return cls(
                vals,
                float(raw["c_b"]),
                float(raw["c_s"]),
                float(raw.get("c_gamma", C_GAMMA)),
                se,
                float(raw.get("v_ref", 0.0)),
                float(raw.get("v_scale", 1.0)),
                terms,
            )
        except (TypeError, ValueError):
            raise InputFileError(f"{where}: parameters must be numbers") from None


def _baseline_values(raw: dict, where: str) -> tuple[dict, dict]:
    """(values, standard errors) of c1..c9 from a chamber entry of layout 2 or 1."""
    if "baseline" in raw:
        items = raw["baseline"]
        if not isinstance(items, list):
            raise InputFileError(f"{where}: 'baseline' must be a list of terms")
        params = [p for d in items for p in term_from_dict(d, f"{where}: baseline", "pneumatics").parameters]
        got = {p.name: p for p in params}
        missing = [n for n in NAMES if n not in got]
        if missing:
            raise InputFileError(f"{where}: the baseline lacks {', '.join(missing)}")
        return {n: got[n].value for n in NAMES}, {n: got[n].stderr for n in NAMES}
    missing = [k for k in NAMES if k not in raw]
    if missing:
        raise InputFileError(f"{where}: missing {', '.join(missing)}")
    return {n: float(raw[n]) for n in NAMES}, {n: float(v) for n, v in (raw.get("stderr") or {}).items()}
