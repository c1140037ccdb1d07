"""``transmission_backlash``: play in a joint's transmission, between the motor (whose encoder the
log reads) and the link (issue #31: a backlash was named a torque lag).

The link angle is the motor angle through a play (hysteresis) operator of half-width b: the
link stays where it is until the motor has taken up the gap, then follows it b behind,

.. math:: q^{link}_t = \\min\\bigl(\\max(q^{link}_{t-1},\\ q_t - b),\\ q_t + b\\bigr),

and the rigid body's torque is the link's: eq. (3.30) with the regressor f(q^link, qd, qdd). It
is an *input* filter: every column of the model that depends on the angles (the rigid body's
regressor, eq. 3.29-3.30, and every position-dependent term: a spring, a payload, a position
friction's region) is evaluated at q^link instead of the logged q. The velocity and acceleration
are kept as logged: the link's equal the motor's while engaged, and differ only across the gap
(a first-order approximation: the short crossings of the play are left out). Given b the model
is linear in its parameters as before; b is searched with them re-solved at every trial
(:mod:`diegocal.diagnose.dynamics_filters`).

The operator runs along the samples in time order, restarted at a gap in time (a step over 1.5 ×
the median, as :func:`~diegocal.sgp.terms.lag_filter`), each run starting with the link at the
first sample's angle (centred in the play: which side the gear rests on is not known there).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from diegocal.causes import MAX_BACKLASH_RAD
from diegocal.sgp.proposal import Proposal
from diegocal.terms import make_term

CAUSE = "transmission_backlash"
#: transmission_backlash variants ``diagnose`` offers: half-widths, rad (the fit refines it within
#: the registry's bounds); the column of b is the torque's change per unit of b, its coefficient ≈ b
HALF_WIDTH_GRID = (0.003, 0.01, 0.03, MAX_BACKLASH_RAD)


def is_input_filter(term) -> bool:
    """True for a cause that filters the model's inputs (the angles) rather than its columns."""
    return term.cause == CAUSE


def play(x: np.ndarray, time: np.ndarray | None, half_width: float) -> np.ndarray:
    """The link angle (T,) rad of a motor angle ``x`` (T,) rad through a play of ``half_width``
    rad (module docstring), along the samples; ``time`` (T,) s restarts it at a gap (None: one
    run). A half-width of 0 returns a copy of x."""
    x = np.asarray(x, float)
    out = x.copy()
    if half_width <= 0 or x.size < 2:
        return out
    cuts = [0, x.size]
    if time is not None:
        steps = np.diff(np.asarray(time, float))
        cuts[1:1] = (np.flatnonzero(steps > 1.5 * float(np.median(steps))) + 1).tolist()
    b = float(half_width)
    for s, e in zip(cuts[:-1], cuts[1:], strict=True):
        low, high = _clamps_so_far(x[s:e] - b, x[s:e] + b)
        out[s:e] = np.minimum(np.maximum(x[s], low), high)
    return out


def _clamps_so_far(low: np.ndarray, high: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The recursion y_t = clamp(y_{t−1}, low_t, high_t) as one clamp per sample of the first
    sample's y: a clamp followed by a clamp is a clamp, [clamp(l₁, l₂, h₂), clamp(h₁, l₂, h₂)],
    so the clamps of every prefix come from a doubling scan (log₂ T steps of whole-array minima
    and maxima: exact, as the loop is, and several times faster than a Python loop)."""
    low, high = low.copy(), high.copy()
    d = 1
    while d < low.size:
        earlier_low = np.minimum(np.maximum(low[:-d], low[d:]), high[d:])
        earlier_high = np.minimum(np.maximum(high[:-d], low[d:]), high[d:])
        low[d:], high[d:] = earlier_low, earlier_high
        d *= 2
    return low, high


def link_angles(terms, robot, q: np.ndarray, time: np.ndarray | None) -> np.ndarray:
    """q (T, n) rad with each ``transmission_backlash`` term's joint through its play (its
    ``half_width`` as given); q itself when there is none."""
    found = [t for t in terms if is_input_filter(t)]
    if not found:
        return q
    out = np.array(q, float, copy=True)
    for t in found:
        j = robot.joint_index(t.channel)
        out[:, j] = play(out[:, j], time, float(t.values[0]))
    return out


def backlash_proposals(cause: str, ctx) -> list:
    """A transmission backlash on each joint, a family over :data:`HALF_WIDTH_GRID`: its change to
    the torque per unit of half-width on *every* joint (a play on joint j moves the link angle of
    joint j, so the gravity and inertia torques of the joints that carry it too), to first order
    ∂τ/∂q_j · (play_b(q_j) − q_j) / b, ∂τ/∂q_j the rigid body's at the URDF's inertias
    (``ctx.sensitivity``, :class:`AngleSensitivity`; the fit that adds the term evaluates the
    model's own columns at the link angles). The columns are made a chunk of rows at a time
    (:class:`PlayColumn`): a long log's candidates hold a float32 shift per sample, no column.
    Judged on every joint's residual, as a gain is. ``ctx``: :class:`~diegocal.sgp.terms.Context`."""
    if ctx.sensitivity is None:
        return []
    out = []
    for j in ctx.joints:
        if (cause, j) in ctx.have:
            continue
        i = ctx.robot.joint_index(j)
        for b in HALF_WIDTH_GRID:
            shift = ctx.sensitivity.shift(i, b)
            cols = {k: PlayColumn(ctx.sensitivity, r, i, shift) for r, k in enumerate(ctx.joints)}
            out.append(Proposal(make_term(cause, j, {"half_width": b}), f"{cause}:{j}", cols))
    return out


class AngleSensitivity:
    """∂τ/∂q (m, k, n) of a motion q, qd, qdd (T, n): the rigid body's at the URDF's inertias
    (pinocchio's RNEA derivatives), torque rows ``rows``, on the samples asked; the last samples'
    kept (the candidates' columns are filled one chunk of samples at a time, every candidate's in
    turn); with its ``time`` (T,) s, each joint's play shifts too (:meth:`shift`)."""

    def __init__(self, robot, q, qd, qdd, rows, time=None):
        self.model = robot.model
        self.q, self.qd, self.qdd, self.time = q, qd, qdd, time
        self.rows = np.asarray(rows, int)
        self._key, self._value = None, None
        self._shifts: dict = {}

    def shift(self, i: int, half_width: float) -> np.ndarray:
        """(T,) float32 in [-1, 1]: (play_b(q_i) − q_i) / b of joint index i along the motion's
        ``time``, made once per joint and half-width (every round of a diagnosis proposes the same)."""
        key = (i, half_width)
        if key not in self._shifts:
            x = np.asarray(self.q[:, i], float)
            self._shifts[key] = ((play(x, self.time, half_width) - x) / half_width).astype(np.float32)
        return self._shifts[key]

    def at(self, idx) -> np.ndarray:
        idx = np.asarray(idx)
        idx = np.flatnonzero(idx) if idx.dtype == bool else idx
        key = (idx.size, int(idx[0]), int(idx[-1]), int(idx.sum())) if idx.size else (0,)
        if key != self._key:
            data = self.model.createData()
            out = np.empty((idx.size, self.rows.size, self.model.nv))
            for m, t in enumerate(idx):
                out[m] = pin.computeRNEADerivatives(self.model, data, self.q[t], self.qd[t], self.qdd[t])[0][self.rows]
            self._key, self._value = key, out
        return self._value


class PlayColumn:
    """A backlash candidate's column (T, 1) on torque row ``r``: ∂τ_r/∂q_i · shift, made for the
    rows asked (``column[rows]``); ``shift`` (T,) the play's (play_b(q_i) − q_i) / b."""

    def __init__(self, sensitivity: AngleSensitivity, r: int, i: int, shift: np.ndarray):
        self.sensitivity, self.r, self.i, self.shift = sensitivity, r, i, shift
        self.shape = (shift.shape[0], 1)

    def __getitem__(self, rows) -> np.ndarray:
        return (self.sensitivity.at(rows)[:, self.r, self.i] * self.shift[rows])[:, None]
