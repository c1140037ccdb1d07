"""The diagnosis's data faults (:func:`~diegocal.diagnose.engine.run_unit`, step 2's first part):
each fault an adapter detects (marker outliers, swapped labels, a pose whose markers are another
pose's) is tried by refitting the model with it, scored on the held-out blocks, and is a finding
when writing it off removes ``min_gain`` of the held-out error. A cause of the ``term`` role that
an adapter can only try whole, not as linear columns (a mocap clock seconds off), goes through the
same door: added when it removes ``min_gain``, declined otherwise (never kept as a minor fault);
once added, the faults are detected again on the model it moved.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from diegocal.causes import CAUSES
from diegocal.diagnose.types import Finding, fitted_form


def heldout_removed(finding: Finding) -> float:
    """The share of the held-out mean squared error a finding removes (its gain is an RMSE
    reduction; NaN where it has none): what ``min_gain`` bars, for a term as for a fault."""
    red = finding.gain().get("reduction", float("nan"))
    return 1.0 - (1.0 - red) ** 2 if np.isfinite(red) else float("nan")


def write_off(adapter, fitted, res, train, held, options, say, unit: str) -> tuple:
    """(fitted, terms, exclude, findings, minor faults) once ``adapter``'s faults, detected on
    ``fitted`` (the baseline) and its residuals ``res``, are tried in the adapter's order. A minor
    fault (under ``min_gain``) is still written off unless that raises the held-out error (a swap
    of two labels in the training blocks barely moves the fit, yet its frames make a common
    backlash significant); ``exclude`` holds the readings written off (channel -> (T,) bool)."""
    faults = getattr(adapter, "faults", None)
    pending = list(faults(fitted, res)) if faults else []
    exclude: dict = {}
    findings: list[Finding] = []
    minor: list[Finding] = []
    terms: tuple = ()
    tried: set = set()
    while pending:
        fault = pending.pop(0)
        tried.add(fault.term.cause)
        role = _role(fault.term)
        trial = dict(exclude)
        if fault.exclude:
            for c, m in fault.readings.items():
                trial[c] = np.asarray(trial.get(c, np.zeros_like(m, bool)), bool) | np.asarray(m, bool)
        new = adapter.fit(terms + (fault.term,), train)
        before, after = adapter.score(fitted, held, trial), adapter.score(new, held, trial)
        term = fault.term if role != "term" else fitted_form(fault.term, adapter.terms(new))
        finding = Finding(term, role, before, after, dict(fault.evidence, channels=list(fault.readings)))
        removed = heldout_removed(finding)
        what = f"{fault.term.cause} on {fault.term.channel}{unit}"
        if not removed >= options.min_gain and role == "term":
            say(f"{what}: removes {removed:.1%} of the held-out error (under {options.min_gain:.0%}): declined")
            continue
        if not removed >= options.min_gain:  # a minor fault: no finding
            written_off = bool(removed >= 0.0)  # the readings repaired all the same: they mislead the tests
            say(
                f"{what}: writing it off removes {removed:.1%} of the held-out error (under "
                f"{options.min_gain:.0%}): no finding, " + ("written off" if written_off else "left alone")
            )
            minor.append(replace(finding, evidence={**finding.evidence, "written_off": written_off}))
            if not written_off:
                continue
        else:
            findings.append(finding)
            say(f"found {what}")
        exclude = trial
        fitted, terms = new, adapter.terms(new)
        if role == "term":  # the model moved: the readings' faults are judged on the new one
            pending = [f for f in faults(fitted, adapter.residuals(fitted)) if f.term.cause not in tried]
    return fitted, terms, exclude, findings, minor


def _role(term) -> str:
    """A fault's kind: "term" for a registry cause of that role tried whole (a clock far off),
    "fault" for every other (an adapter's own fault need not be in the registry)."""
    entry = CAUSES.get(term.cause)
    return "term" if entry is not None and entry.role == "term" else "fault"
