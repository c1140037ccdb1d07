"""The STAC section's words about what a calibration estimated and held, and its units.

Which gains and biases the fit estimated and which it held at nominal, with the reason: an
encoder's gain is 1 by design; a gauge bias stays at its sensors.yaml value because no marker can
fix its joint's zero (calib.yaml ``gauges``); an unobservable pot keeps gain and bias (calib.yaml
``unobservable``). Each sensor type's numbers are written in its own unit (:data:`READING_UNITS`:
V for pots, rad for encoders, m for markers), a thousandth at a time (:func:`milli`).
"""

from __future__ import annotations

from diegocal.report.stac_plots import pot_units_pooled

MM = 1000.0
#: Units written a thousandth at a time (the size of calibration residuals and noise).
MILLI = {"m": "mm", "V": "mV", "rad": "mrad"}


def milli(value: float, unit: str) -> tuple[float, str]:
    """(value, unit) a thousandth at a time where the unit has a name for it (m, V, rad)."""
    base = unit.split()[0] if unit else unit
    return (MM * value, MILLI[base]) if base in MILLI else (value, unit)


def kinds_of(robot) -> dict:
    return {p.name: p.kind for p in robot.sensors.pots} if robot is not None else {}


def _names(names) -> str:
    names = list(names)
    return names[0] if len(names) == 1 else ", ".join(names[:-1]) + " and " + names[-1]


def _possessive(names) -> str:
    return _names([f"{n}'s" for n in names])


#: Why a gain or bias was not estimated, by its role (:data:`diegocal.stac.calibration.POT_ROLES`):
#: (one pot, several pots); the held-at-nominal ones are explained in :func:`held_words`.
HELD_WHY = {
    "design": (
        "is 1 by design: an encoder reads its joint's own coordinate, in rad, plus a bias",
        "are 1 by design: an encoder reads its joint's own coordinate, in rad, plus a bias",
    ),
    "gauge": ("is a gauge, held at nominal: see below", "are gauges, held at nominal: see below"),
    "unobservable": ("is unobservable, held at nominal: see below", "are unobservable, held at nominal: see below"),
    "nominal": ("has no standard error", "have no standard error"),
}


def estimated_words(cal, robot=None) -> str:
    """Which gains and biases the fit estimated, in a sentence, naming the pots it did not and why."""
    roles = cal.pot_roles(kinds_of(robot))
    P = len(roles)
    if not P:
        return ""
    parts = []
    for k, what in enumerate(("gains", "biases")):
        held = [n for n, r in roles.items() if r[k] != "estimated"]
        if not held:
            parts.append(f"all {P} {what}")
            continue
        why = []
        for role, (one, many) in HELD_WHY.items():
            pots = [n for n in held if roles[n][k] == role]
            if pots:
                why.append(f"{_possessive(pots)} {one if len(pots) == 1 else many}")
        count = "none" if len(held) == P else f"{P - len(held)}"
        parts.append(f"{count} of the {P} {what} ({'; '.join(why)})")
    return f"It estimated {parts[0]} and {parts[1]}."


def held_words(cal, robot=None) -> list[str]:
    """What the fit held at nominal because the data cannot fix it, and why: gauge biases (and joint
    zeros no pot fixes), unobservable pots, parameters without a standard error or a reason."""
    roles = cal.pot_roles(kinds_of(robot))
    out = []
    records = {g.get("pot"): g for g in cal.gauges}
    gauges = [n for n, r in roles.items() if r[1] == "gauge"]
    if gauges:
        why = "; ".join(f"{n}'s, as {_gauge_reason(records.get(n))}" for n in gauges)
        out.append(
            f"{len(gauges)} pot bias(es) are held at nominal because the markers cannot fix that joint's zero "
            f"(a gauge: {why}), so their standard errors are not given"
        )
    for g in cal.gauges:
        if g.get("pot") is None:
            out.append(f"joint {g['joint']}'s zero is a gauge: {_gauge_reason(g)}")
    unobservable = {u.get("pot"): u.get("reason", "") for u in cal.unobservable}
    unobservable.update({n: "" for n, r in roles.items() if r[1] == "unobservable" and n not in unobservable})
    for reason in dict.fromkeys(_unobservable_reason(r) for r in unobservable.values()):
        pots = [n for n, r in unobservable.items() if _unobservable_reason(r) == reason]
        out.append(f"{len(pots)} pot(s) ({', '.join(sorted(pots))}) keep their nominal gain and bias: {reason}")
    nominal = [n for n, r in roles.items() if "nominal" in r]
    if nominal and cal.method != "nominal":
        out.append(f"parameters of {_names(nominal)} were not estimated (no standard error), for no recorded reason")
    return out


def _gauge_reason(record) -> str:
    """Why a joint's zero is a gauge (calib.yaml's ``gauges[].reason``, less the clause naming the pot)."""
    if not record:
        return "a joint zero the markers cannot fix"
    return "; ".join(c for c in str(record.get("reason", "")).split("; ") if not c.startswith("pot "))


def _unobservable_reason(reason: str) -> str:
    return "no marker moves with their joints" if not reason or reason.startswith("no marker moves") else reason


def sigma_words(cal) -> str:
    """What the σ plot's pot line is (:func:`~diegocal.report.stac_plots.plot_sigma`), in its units."""
    units = pot_units_pooled(cal)
    if len(set(units.values())) > 1:
        each = ", ".join(f"{g} in {u}" for g, u in units.items())
        return (
            f"the pot types read in different units ({each}), so each one's final σ is marked at the last "
            "iteration (the fit's history keeps only their pooled RMS, which has no unit); markers in m"
        )
    return f"pots in {next(iter(units.values()), 'V')} (the RMS over their types), markers in m"
