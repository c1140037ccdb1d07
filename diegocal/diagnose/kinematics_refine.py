"""A found kinematic term refined (:meth:`KinematicsAdapter.fit
<diegocal.diagnose.kinematics.KinematicsAdapter.fit>`): Gauss-Newton steps on its parameters
alternate with STAC's refit of the calibration, one always, more while the term still moves.
"""

from __future__ import annotations

import numpy as np

from diegocal.diagnose.kinematics_clock import clock_tol
from diegocal.stac.terms import POT_CAUSES

#: Refinements at most: one always, more while a term still moves by more than REFINE_TOL of its
#: standard error (a clock shift also while it moves by more than CLOCK_TOL of itself). The term's step and STAC's
#: refit alternate, which converges linearly: on a 60-s diego log a pot's cubic coefficient moved
#: by 0.9, 0.4 and 0.15 of its standard error in the first three steps (truth 0; after one step it
#: was 1.9 SE from it), and a shift of many samples is far from its first, linear, estimate (0.18 s
#: after one step for 0.21 s); on 30-s iCub logs half the clock shifts took a fifth step to come
#: within 2 SE of the truth.
REFINE_MAX = 6
REFINE_TOL = 0.2
CLOCK_TOL = 0.02
#: The causes whose parameters a refinement steps (the rest are fitted by STAC or not continuous).
REFINED = (*POT_CAUSES, "link_offset", "time_offset")
#: A link offset is a URDF's error of millimetres to centimetres. A candidate's linear estimate
#: beyond this (m) lies along a direction the data barely fix (a user trial's Z1 joint 4: dx −1.6 km,
#: dz 6.1 km, where the refinement from zero gives 7.9 mm and leaves dz unfixed): that component
#: starts at zero, where the refinement's pseudo-inverse leaves what the data do not fix.
START_MAX_M = 0.5


def plausible_start(term):
    """``term`` with the components of a displacement (m) beyond :data:`START_MAX_M` started at 0."""
    far = np.array([p.unit == "m" and abs(p.value) > START_MAX_M for p in term.parameters])
    return term.with_values(np.where(far, 0.0, term.values), term.stderrs) if far.any() else term


def moved(before, after, beyond: float) -> bool:
    """Whether a refinement moved a term from ``before`` to ``after``: a refined term's parameter
    by more than REFINE_TOL of its standard error (a NaN error: not moved), a clock shift also by
    more than its tolerance (:func:`~diegocal.diagnose.kinematics_clock.clock_tol`; ``beyond``: the
    largest shift the candidates try). A term new to ``after`` is no move."""
    for was, t in _steps(before, after):
        if t.cause == "time_offset":
            shift = float(t.values[0])
            if abs(shift - float(was.values[0])) > clock_tol(shift, CLOCK_TOL, beyond):
                return True
        if np.any(np.abs(t.values - was.values) > REFINE_TOL * t.stderrs):
            return True
    return False


def _steps(before, after):
    """(the term before, after) of each refined term a step moved (new terms left out)."""
    old = {(t.cause, t.channel): t for t in before}
    for t in after:
        was = old.get((t.cause, t.channel))
        if was is not None and t.cause in REFINED and was.values.shape == t.values.shape:
            yield was, t


def jumped(before, after, period: float) -> bool:
    """Whether a step moved a clock shift by a sample ``period`` or more: the fit before it tracked
    q against another alignment of the markers, and STAC started there can end in another optimum
    (a 30-s iCub log: the shift's standard error three times the cold fit's, 2.7 of it from the
    truth, where the cold fit's was 0.07)."""
    old = {(t.cause, t.channel): t for t in before if t.cause == "time_offset"}
    for t in after:
        was = old.get((t.cause, t.channel))
        if was is not None and abs(float(t.values[0]) - float(was.values[0])) >= period:
            return True
    return False


def refined(adapter, fitted, train: np.ndarray, beyond: float):
    """``fitted`` (the adapter's fit of its terms, tracked on every frame) after its refinements
    (:meth:`KinematicsAdapter.refine_step <diegocal.diagnose.kinematics.KinematicsAdapter.refine_step>`,
    each a Gauss-Newton step and a STAC refit, warm-started unless the step :func:`jumped`):
    whether a step is the last is known from the step alone (:func:`moved`), so the others track q
    on the training frames only, which is all the next step reads. ``beyond``: :func:`moved`'s."""
    period = float(np.median(np.diff(adapter.time))) if adapter.time.size > 1 else 0.0
    for k in range(1, REFINE_MAX + 1):
        step = adapter.refine_step(fitted)
        still = moved(fitted.terms, step, beyond)
        last = k == REFINE_MAX or (k > 1 and not still)
        warm = not jumped(fitted.terms, step, period)
        before = fitted.terms
        fitted = adapter.fit_once(step, train, fitted, warm=warm, track=None if last else train)
        if last:
            break
    if still:  # the cap, not the tolerance, ended it
        fitted.unconverged += (stopped(before, step),)
    return fitted


def stopped(before, after) -> str:
    """In words, a refinement that the cap ended while its last step still moved a term."""
    moves = [
        f"{t.label} by {np.max(np.abs(t.values - was.values) / t.stderrs):.2g} SE"
        for was, t in _steps(before, after)
        if np.all(t.stderrs > 0)
    ]
    return (
        f"the found terms' refinement stopped at its cap of {REFINE_MAX} step(s) while its last step still moved "
        f"{', '.join(moves) or 'a term'} (more than {REFINE_TOL:g} SE): their values and ± are not at the fixed point"
    )
