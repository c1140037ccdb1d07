"""A mocap clock seconds off the robot's (issue #31): two loggers started apart. The clock-shift
candidates (:data:`~diegocal.diagnose.kinematics.TIME_SHIFTS`) reach half a second and are
linearised at the baseline, whose calibration has absorbed much of a larger shift (a 1-s shift
showed as 9 % of itself); a 0.6-s shift was left `unexplained` on the pots. The shift the training
frames' own motion suggests is instead tried whole, as a data fault is: the model refitted with
the clock shifted, named when it removes ``min_gain`` of the held-out error.

The motion: the markers' mean speed explained, by non-negative least squares, by the pots' speeds
(each marker speeds up when a joint before it turns; none slows it down), at each shift of the
markers' clock; the shift that leaves the least of it unexplained. The import's estimator (one
correlation of marker speed with the norm of the pot speeds, :mod:`diegocal.io.importers.clocks`)
found 2 of 8 such shifts on the independent generator's UR5 and iCub, whose joints move one
after another; this one found 8 of 8, and 0.0 on their clean logs.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import nnls

from diegocal.diagnose.types import Fault
from diegocal.io.importers.clocks import ENVELOPE_HZ, motion_speed
from diegocal.io.importers.signals import lowpass, uniform_grid
from diegocal.terms import make_term

#: Shifts tried, either sign (s): a clock further off is the import's to align (`time_offset: auto`).
MAX_SHIFT = 10.0
#: The speeds are compared on a grid this fine (Hz): they hold nothing above ENVELOPE_HZ.
GRID_HZ = 20.0
#: A shift is tried when it leaves at most this share of what no shift leaves unexplained (a
#: shift that explains little more is no clock's: on a clean 15-s diego log 0.6 of it at 0.9 s).
BETTER = 0.5
#: ... and when it explains at least this share of the markers' speed variance more than no shift
#: does: where the pots explain nearly all of it unshifted, the clocks agree, and a shift that
#: explains a little more is the motion repeating itself (clean 15-s diego logs: 0.013-0.017 more
#: at 0.85 s, each tried in five slow refits and declined; shifts of 0.6-2 s on the finger and on
#: the independent generator's UR5 and iCub: 0.16-0.98 more).
MIN_EXPLAINED = 0.05
#: A shift counts only the pairs of training frames it joins; it must join at least this share.
MIN_PAIRS = 0.5
#: A clock seconds off is refined until it moves by less than this (s): a share of itself, as
#: the candidates' shifts are, stopped a 0.6-s shift 2 ms (2.5 standard errors) off.
FAR_TOL = 1e-4


def far_shift(time: np.ndarray, pots: np.ndarray, markers: np.ndarray, train: np.ndarray) -> tuple | None:
    """(s, left, left at no shift): the shift of the markers' clock in the ``time_offset``
    convention (markers[t] observe q(t + s)) that leaves the least of the markers' mean speed
    unexplained by the pots' speeds, and those shares; None where nothing moves. Only pairs of
    training frames are read, at least 2 / ENVELOPE_HZ inside their blocks (a frame near a block's
    edge reads its neighbours through the low-pass)."""
    rate = 1.0 / float(np.median(np.diff(time)))
    speed = motion_speed("markers", time, markers, rate)
    if speed is None or pots.shape[0] < 16:
        return None
    grid = uniform_grid(time[0], time[-1], GRID_HZ)
    y = np.interp(grid, *speed)
    smooth = lowpass(np.asarray(pots, float), rate, min(ENVELOPE_HZ, 0.4 * rate), order=2)
    v = np.abs(np.gradient(smooth, time, axis=0))
    X = np.column_stack([np.interp(grid, time, v[:, k]) for k in range(v.shape[1])])
    X = X[:, X.std(axis=0) > 0]
    inside = np.interp(grid, time, np.asarray(train, float)) > 1 - 1e-9
    margin = int(np.ceil(2 * GRID_HZ / ENVELOPE_HZ))
    inside = np.convolve(~inside, np.ones(2 * margin + 1), mode="same") == 0  # eroded by the margin
    if not X.shape[1] or not inside.any():
        return None
    left = {}
    K = int(MAX_SHIFT * GRID_HZ)
    for m in range(-K, K + 1):  # pots at j + m meet markers at j
        j = np.arange(max(0, -m), min(grid.size, grid.size - m))
        ok = inside[j] & inside[j + m]
        if ok.sum() < MIN_PAIRS * inside.sum():
            continue
        A, b = X[j[ok] + m], y[j[ok]]
        A, b = A - A.mean(axis=0), b - b.mean()
        _, rnorm = nnls(A, b)
        left[m] = rnorm**2 / float(b @ b) if b @ b > 0 else 1.0
    if 0 not in left:
        return None
    best = min(left, key=left.get)
    step = 0.0  # between grid steps: the parabola through the least and its neighbours
    if best - 1 in left and best + 1 in left:
        lo, mid, hi = left[best - 1], left[best], left[best + 1]
        step = 0.5 * (lo - hi) / (lo - 2 * mid + hi) if lo - 2 * mid + hi > 0 else 0.0
    return (best + step) / GRID_HZ, left[best], left[0]


def clock_fault(adapter, fitted, beyond: float) -> Fault | None:
    """A ``time_offset`` of the shift :func:`far_shift` finds on the training frames of
    ``fitted`` (a KinFit of ``adapter``, a KinematicsAdapter), when it lies beyond ``beyond`` s (the
    candidates' reach) and leaves at most BETTER of what no shift leaves; it predicts every marker
    (no reading is written off). None for a model that shifts the clock already."""
    if any(t.cause == "time_offset" for t in fitted.terms):
        return None
    est = far_shift(adapter.time, adapter.raw_pots, adapter.log.stream("markers").data, fitted.train)
    if est is None or not abs(est[0]) > beyond or not est[1] <= BETTER * est[2] or not est[2] - est[1] >= MIN_EXPLAINED:
        return None
    term = make_term("time_offset", "markers").with_linear_values([est[0]])
    readings = {m: np.zeros(adapter.time.size, bool) for m in adapter.marker_names}  # scored on every marker
    evidence = {
        "estimate_s": est[0],
        "speed_left": est[1],
        "speed_left_unshifted": est[2],
        "from": "marker speed against the pots' speeds, training frames",
    }
    return Fault(term, readings, exclude=False, evidence=evidence)


def far_clock(terms, beyond: float) -> bool:
    """Whether ``terms`` shift the markers' clock by more than ``beyond`` s: a fit of them does not
    start from the baseline's, whose marker positions and mocap frame fit the unshifted clock (from
    there a 0.8-s shift stayed 46 ms off)."""
    return any(t.cause == "time_offset" and abs(float(t.values[0])) > beyond for t in terms)


def clock_tol(shift: float, rel: float, beyond: float) -> float:
    """How little a refined clock shift must move to stop: ``rel`` of itself within the candidates'
    reach ``beyond``, FAR_TOL beyond it."""
    return rel * max(abs(shift), 1e-3) if abs(shift) <= beyond else FAR_TOL
