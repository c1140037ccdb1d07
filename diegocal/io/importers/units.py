"""Units a lab file may use, and the factor that takes each to the log's unit (DESIGN.md table).

Every stream of a diegocal log has one unit: q in rad (m for a prismatic joint), qd in rad/s,
qdd in rad/s², tau in N·m (N), markers in m, valve in V. ``pots`` and ``pressure`` are in sensor
units (sensors.yaml's gains and the chambers' supply pressure are stated in them), so any unit
name is accepted there and nothing is converted. Current (A, mA) becomes torque only through a
torque constant (N·m/A) that the map states.
"""

from __future__ import annotations

import difflib
import math

from diegocal.errors import DiegocalError

DEG = math.pi / 180.0

#: Unit families: name -> factor to the SI unit of the family.
_POSITION = {"rad": 1.0, "mrad": 1e-3, "deg": DEG, "degree": DEG, "degrees": DEG, "°": DEG,
             "m": 1.0, "cm": 1e-2, "mm": 1e-3}
_VELOCITY = {"rad/s": 1.0, "deg/s": DEG, "rpm": 2.0 * math.pi / 60.0,
             "m/s": 1.0, "mm/s": 1e-3}
_ACCELERATION = {f"{u}{sq}": f for u, f in (("rad/s", 1.0), ("deg/s", DEG), ("m/s", 1.0), ("mm/s", 1e-3))
                 for sq in ("^2", "2", "²")}
_EFFORT = {"N·m": 1.0, "N.m": 1.0, "Nm": 1.0, "N*m": 1.0, "mN·m": 1e-3, "mNm": 1e-3,
           "N": 1.0, "kN": 1e3}
#: Current units: converted with a torque constant (N·m/A) stated in the map.
CURRENT = {"A": 1.0, "mA": 1e-3}
_LENGTH = {"m": 1.0, "cm": 1e-2, "mm": 1e-3}
_VOLTAGE = {"V": 1.0, "mV": 1e-3}

#: Units accepted per stream; None: sensor units, any name, no conversion.
STREAM_UNITS: dict[str, dict[str, float] | None] = {
    "q": _POSITION,
    "qd": _VELOCITY,
    "qdd": _ACCELERATION,
    "tau": {**_EFFORT, **CURRENT},
    "markers": _LENGTH,
    "pots": None,
    "pressure": None,
    "valve": _VOLTAGE,
}

#: The log's unit per stream, as DESIGN.md states it (for messages and summaries).
LOG_UNIT = {"q": "rad (m)", "qd": "rad/s (m/s)", "qdd": "rad/s² (m/s²)", "tau": "N·m (N)",
            "markers": "m", "pots": "sensor units", "pressure": "sensor units", "valve": "V"}

#: Time-column units -> seconds.
TIME_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "µs": 1e-6, "ns": 1e-9}


class UnitError(DiegocalError, ValueError):
    """A unit name is unknown for the stream it is given to."""


def close_match(word: str, candidates) -> str:
    """`` — did you mean 'x'?`` when a candidate is close to ``word`` (difflib), else ''."""
    found = difflib.get_close_matches(str(word), [str(c) for c in candidates], n=1, cutoff=0.6)
    return f" — did you mean {found[0]!r}?" if found else ""


def factor(stream: str, unit: str) -> float:
    """Factor taking ``unit`` to the log's unit of ``stream`` (1.0 for sensor units).

    Raises :class:`UnitError` with the known units and a close match when ``unit`` is unknown.
    Current units return their factor to A; the caller multiplies by the torque constant.
    """
    known = STREAM_UNITS[stream]
    if known is None:
        return 1.0
    unit = str(unit).strip()
    if unit in known:
        return known[unit]
    raise UnitError(f"unknown unit {unit!r} for stream '{stream}' (known: {', '.join(known)})"
                    + close_match(unit, known))


def time_factor(unit: str) -> float:
    """Seconds per ``unit`` of a time column."""
    if unit in TIME_UNITS:
        return TIME_UNITS[unit]
    raise UnitError(f"unknown time unit {unit!r} (known: {', '.join(TIME_UNITS)})"
                    + close_match(unit, TIME_UNITS))


def is_current(stream: str, unit: str) -> bool:
    return stream == "tau" and str(unit).strip() in CURRENT
