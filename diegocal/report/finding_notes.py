"""The sentences a diagnosis report adds to a finding beyond its cause, gain and parameters: what
the data fix of a slipped marker or a torque sensor's gain, why no cause is named where a term
stood in, what else the same model is (a lasting supply sag is a pressure sensor's span error), and
how values are printed."""

from __future__ import annotations

import numpy as np

from diegocal.causes import search_end


def notes(f: dict) -> str:
    """Every note of finding ``f`` (a diagnosis.yaml finding), each a sentence or more, in order."""
    return gauge_text(f) + stand_in_text(f) + span_error_text(f) + relative_gain_text(f) + trade_text(f)


#: Causes whose ``extra.correlation`` is a trade with the baseline's parameters that their ± cannot
#: show as a bias (a valve delay's with the sensor lag is in its ±: :mod:`~diegocal.diagnose.pneumatics_terms`).
TRADING = ("chamber_leak", "supply_droop")


def trade_text(f: dict) -> str:
    """What a leak's or a supply sag's estimate trades with (``extra.correlation``: the valve's
    parameters c1..c9 it correlates with): its ± is marginal over them, but
    an error of the model's own that moves them moves it too (a leak's ± covered an orifice's rate
    in none of 32 logs of an independent generator, the valve's centre c1 taking the rest)."""
    pairs = (f.get("extra") or {}).get("correlation") or {}
    if not pairs or f.get("cause") not in TRADING:
        return ""
    listed = ", ".join(f"{name} (ρ = {rho:+.2f})" for name, rho in sorted(pairs.items(), key=lambda x: -abs(x[1])))
    return (f" Its estimate trades with {listed}: where the model's own error moves those, it moves this "
            "value too, by more than its ± says.")


def relative_gain_text(f: dict) -> str:
    """What the data fix of a torque sensor's gain where the rigid body's inertial parameters are
    identified (``extra.relative``): a common scale of every joint's torque is theirs, so only the
    joints' gains against each other."""
    if not (f.get("extra") or {}).get("relative"):
        return ""
    return (f" With the rigid body's inertial parameters identified, a common scale of every joint's torque is "
            f"theirs: this is {f['channel']}'s gain against the other joints' (gains of the opposite sign on "
            "every other joint fit the same); --inertia nominal or a torque known on one joint fixes it.")


def span_error_text(f: dict) -> str:
    """What a lasting supply sag also is to the chamber model (``extra.span_error``)."""
    extra = f.get("extra") or {}
    k = extra.get("span_error")
    if k is None or f.get("cause") != "supply_droop" or extra.get("shape"):
        return ""
    return (f" To the chamber model this sag is the same as a pressure sensor reading {abs(k):.2%} of its span "
            f"{'low' if k < 0 else 'high'}: the data cannot tell the two apart (a gauge on the supply, or the "
            "sensor checked against one, can).")


def gauge_text(f: dict) -> str:
    """What the data fix of a slipped marker's move whose direction is the fit's gauge (``extra.gauge``)."""
    if not (g := (f.get("extra") or {}).get("gauge")):
        return ""
    pair = (g["length"], g["along_axis"])
    length, along = (f"{value_text(v['value'], v['stderr'])} ± {v['stderr']:.2g} m" for v in pair)
    return (f" Its direction about joint {g['joint']}'s axis is the calibration's convention for that joint's zero, "
            f"not the data's, and so are the components above: the data fix its length, {length}, and its "
            f"component along the axis, {along}.")


def stand_in_text(f: dict) -> str:
    """Why an ``unexplained`` finding names no cause although a term was significant: the term
    explained far less than a flexible function of the channel's own state, or less than a term
    declined on it (a stand-in), or was itself declined for a value beyond its search."""
    ev = f.get("evidence") or {}
    if not (stood := ev.get("stand_in")):
        return ""
    gain, declined = ev.get("validation_gain", float("nan")), ev.get("declined")
    if rival := ev.get("rival"):
        return (f" The best term of the vocabulary, {stood['term']}, removes "
                f"{rival['term_open_loop_validation_gain']:.0%} of the open-loop validation error where "
                f"{rival['model']}, a shape no cause names, removes {rival['open_loop_validation_gain']:.0%}: "
                "it would stand in for it, so no cause is named.")
    if declined and declined["term"] == stood["term"]:  # declined itself: a value beyond its search
        return (f" {stood['term']} explains {stood['validation_gain']:.0%} of the validation error but was declined "
                f"({declined['why']}): the structure is real, the value it wants beyond what the cause describes, "
                "so no cause is named.")
    beaten = (f"{declined['term']} explained {gain:.0%} and was declined ({declined['why']}): it would stand in "
              "for what that term fits" if declined else f"a flexible function of {f['channel']}'s own state "
              f"explains {gain:.0%}: it would stand in for structure of another shape")
    return (f" The best term of the vocabulary, {stood['term']}, explains {stood['validation_gain']:.0%} of the "
            f"validation error where {beaten}, so no cause is named.")


def stderr_of(v: dict):
    """A parameter's standard error: ``stderr`` (file layout 2) or ``std`` (layout 1)."""
    return v.get("stderr", v.get("std"))


def value_text(value: float, se) -> str:
    """A fitted value to the digits its standard error gives it (two of the SE's): a 1-s clock
    shift of −0.99963 ± 0.00027 s is not "−1 ± 0.00027"; three significant digits without one."""
    if se is None or not np.isfinite(se) or se <= 0:
        return f"{value:.3g}"
    decimals = int(min(max(1 - np.floor(np.log10(se)), 0), 10))
    return f"{value:.{decimals}f}"


def _pressure_unit(unit: str, f: dict) -> str:
    """A pneumatic parameter's unit with "pu" (the model's pressure unit, that of the log's pressure
    stream) written as the finding's own unit (kPa)."""
    pressure = f.get("unit") if f.get("domain") == "pneumatics" or f.get("unit") == "kPa" else None
    return " ".join(pressure if w == "pu" and pressure else w for w in unit.split(" "))


def _at_bound(f: dict, name: str, v: dict) -> str:
    """Words for a parameter that ends at the upper bound of its search (the registry's): the data
    want more than the cause takes, so its fit stands in for something it does not describe."""
    spec = search_end(f.get("cause", ""), name, v["value"])
    if spec is None:
        return ""
    return f" (the end of its search, {spec.upper:g}: the data want more, which this cause does not describe)"


def parameters_text(f: dict) -> str:
    """A finding's fitted parameters in words, each to the digits its standard error gives it."""
    p = f.get("parameters") or {}
    if not p or f["cause"] == "unexplained":
        return ""
    hidden = 0
    if len(p) > 4:  # a payload's ten inertial parameters: the identified ones (with a standard error)
        hidden = sum(stderr_of(v) is None for v in p.values())
        p = dict(list({k: v for k, v in p.items() if stderr_of(v) is not None}.items())[:4])
    parts, unfixed = [], []
    some_se = any(stderr_of(v) is not None for v in p.values())
    for name, v in p.items():
        if v.get("value") is None:
            continue
        if some_se and stderr_of(v) is None:  # beside parameters with one: a direction the data do not fix
            unfixed.append(name)
            continue
        s = f"{name} = {value_text(v['value'], stderr_of(v))}"
        if stderr_of(v) is not None:
            s += f" ± {stderr_of(v):.2g}"
        parts.append(s + (f" {_pressure_unit(v['unit'], f)}" if v.get("unit") else "") + _at_bound(f, name, v))
    if hidden:
        parts.append(f"{hidden} parameter(s) not identified by these data")
    if unfixed:
        parts.append(f"{', '.join(unfixed)} not fixed by these data (left at the start)")
    return (" Fitted: " + ", ".join(parts) + ".") if parts else ""
