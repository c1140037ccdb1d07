"""Units a lab file may use, and the factor that takes each to the log's unit (DESIGN.md table).

Every stream of a diegocal log has one unit: q in rad (m for a prismatic joint), qd in rad/s,
qdd in rad/s², tau in N·m (N), markers in m, valve in V. ``pots`` and ``pressure`` are in sensor
units (sensors.yaml's gains and the chambers' supply pressure are stated in them), so any unit
name is accepted there; only a pot's voltage is brought to V (mV beside V would make one pot's
gain a thousand times another's). Current (A, mA) becomes torque only through a
torque constant (N·m/A) that the map states.
"""

from __future__ import annotations

import difflib
import math
import re

from diegocal.errors import DiegocalError

DEG = math.pi / 180.0

#: Unit families: name -> factor to the SI unit of the family; angular and linear kept apart so a
#: revolute joint cannot be given a length, nor a prismatic joint an angle.
_ANGLE = {"rad": 1.0, "mrad": 1e-3, "deg": DEG, "degree": DEG, "degrees": DEG, "°": DEG}
_LENGTH = {"m": 1.0, "cm": 1e-2, "mm": 1e-3}
_ANGULAR_VELOCITY = {"rad/s": 1.0, "deg/s": DEG, "rpm": 2.0 * math.pi / 60.0}
_LINEAR_VELOCITY = {"m/s": 1.0, "mm/s": 1e-3}
_ANGULAR_ACCELERATION = {f"{u}{sq}": f for u, f in (("rad/s", 1.0), ("deg/s", DEG)) for sq in ("^2", "2", "²")}
_LINEAR_ACCELERATION = {f"{u}{sq}": f for u, f in (("m/s", 1.0), ("mm/s", 1e-3)) for sq in ("^2", "2", "²")}
_TORQUE = {"N·m": 1.0, "N.m": 1.0, "Nm": 1.0, "N*m": 1.0, "mN·m": 1e-3, "mNm": 1e-3}
_FORCE = {"N": 1.0, "kN": 1e3}
#: Current units: converted with a torque constant (N·m/A) stated in the map.
CURRENT = {"A": 1.0, "mA": 1e-3}
#: Voltages: pots are "sensor units (V)" (DESIGN.md), so a pot read in mV is brought to V; a pot in
#: any other unit (counts, bits) is kept as it is.
_VOLTAGE = {"V": 1.0, "mV": 1e-3, "uV": 1e-6, "µV": 1e-6}
#: Units of a prismatic joint's streams (m, m/s, m/s², N).
LINEAR = frozenset({*_LENGTH, *_LINEAR_VELOCITY, *_LINEAR_ACCELERATION, *_FORCE})

#: Units accepted per stream; None: sensor units, any name, no conversion.
STREAM_UNITS: dict[str, dict[str, float] | None] = {
    "q": {**_ANGLE, **_LENGTH},
    "qd": {**_ANGULAR_VELOCITY, **_LINEAR_VELOCITY},
    "qdd": {**_ANGULAR_ACCELERATION, **_LINEAR_ACCELERATION},
    "tau": {**_TORQUE, **_FORCE, **CURRENT},
    "markers": _LENGTH,
    "pots": None,
    "pressure": None,
    "valve": _VOLTAGE,
}

#: The log's unit per stream, as DESIGN.md states it (for messages and summaries).
LOG_UNIT = {"q": "rad (m)", "qd": "rad/s (m/s)", "qdd": "rad/s² (m/s²)", "tau": "N·m (N)",
            "markers": "m", "pots": "sensor units (V)", "pressure": "sensor units", "valve": "V"}
#: The log's unit of a joint stream for a revolute and a prismatic joint.
JOINT_UNIT = {"q": ("rad", "m"), "qd": ("rad/s", "m/s"), "qdd": ("rad/s²", "m/s²"), "tau": ("N·m", "N")}

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
    unit = str(unit).strip()
    if known is None:
        return _voltage(unit) or 1.0 if stream == "pots" else 1.0
    if unit in known:
        return known[unit]
    raise UnitError(f"unknown unit {unit!r} for stream '{stream}' (known: {', '.join(known)})"
                    + close_match(unit, known))


#: A voltage unit's name by its lower case ('mv' is mV: no pot reads megavolts).
_VOLT_NAMES = {k.lower(): k for k in _VOLTAGE}


def _voltage(unit: str) -> float | None:
    """The factor of a voltage unit to V, its case aside; None for another unit."""
    name = _VOLT_NAMES.get(str(unit).strip().lower())
    return None if name is None else _VOLTAGE[name]


#: Every unit name this module knows (a column header's ``[unit]`` is one of them, or not a unit).
KNOWN_UNITS = frozenset(
    {u for table in STREAM_UNITS.values() if table for u in table} | set(_VOLTAGE) | set(TIME_UNITS) | set(CURRENT)
)


def header_unit(column: str) -> str | None:
    """The unit a lab table's column header states at its end, ``x [mV]`` or ``x (mV)``, when it is
    one this module knows (a header's ``(joint 1)`` is a name, not a unit); else None."""
    m = re.search(r"[\[(]\s*([^\])]+?)\s*[\])]\s*$", str(column))
    if m is None:
        return None
    unit = m.group(1)
    return unit if unit in KNOWN_UNITS else _VOLT_NAMES.get(unit.lower())  # `[mv]` is mV, as `unit: mv`


def target_unit(stream: str, unit: str) -> str:
    """The unit ``unit`` becomes in the log, for summaries: V for a pot in mV, else the stream's."""
    if stream == "pots":
        return "V" if _voltage(unit) is not None else str(unit)
    return LOG_UNIT[stream]


def check_joint_unit(stream: str, unit: str, joint: str, kind: str) -> None:
    """A revolute joint takes angular units, a prismatic one linear units (m, m/s, N): else UnitError."""
    unit = str(unit).strip()
    if stream not in JOINT_UNIT or kind not in ("revolute", "prismatic") or unit in CURRENT:
        return
    if (unit in LINEAR) != (kind == "prismatic"):
        want = JOINT_UNIT[stream][kind == "prismatic"]
        raise UnitError(f"{stream} of {joint!r}, a {kind} joint, is in {want}, not {unit}")


def time_factor(unit: str) -> float:
    """Seconds per ``unit`` of a time column."""
    if unit in TIME_UNITS:
        return TIME_UNITS[unit]
    raise UnitError(f"unknown time unit {unit!r} (known: {', '.join(TIME_UNITS)})"
                    + close_match(unit, TIME_UNITS))


def is_current(stream: str, unit: str) -> bool:
    return stream == "tau" and str(unit).strip() in CURRENT
