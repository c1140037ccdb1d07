"""Flexible transfer curves of the pots (issue #31, item 1: a wrong name is worse than
``unexplained``). A pot read through a gear with runout, or one that picks up another pot's
signal, is misread by STAC as a q error: tracked jointly with the pots that read the same chain, the
error moves to its neighbours, where a named cause of theirs (a backlash on the next pot) explains
part of it. The engine then asks whether a curve of a neighbour's own reading explains more
(:meth:`KinematicsAdapter.spill_candidates <diegocal.diagnose.kinematics.KinematicsAdapter.spill_candidates>`):
a piecewise-linear function of that pot's model reading with CURVE_KNOTS knots at the quantiles of
its training readings, linearised like any pot term (projected out of q and of the pots' gains and
biases, :class:`~diegocal.diagnose.kinematics_sweep.Sweep`). Its term is ``unexplained``: the
curve is a shape, never a cause.
"""

from __future__ import annotations

from functools import partial

import numpy as np

from diegocal.diagnose.kinematics_sweep import Columns, Sweep
from diegocal.diagnose.types import Candidate
from diegocal.terms import Parameter, Term

#: Knots of a pot's flexible curve: enough for a runout of six periods over the visited range.
CURVE_KNOTS = 13


def hat_basis(x: np.ndarray, knots: np.ndarray) -> np.ndarray:
    """(T, K) piecewise-linear hat functions of ``x`` (T,) on increasing ``knots`` (K,), x held
    at the end knots beyond them."""
    xc = np.clip(np.nan_to_num(x, nan=knots[0]), knots[0], knots[-1])
    k = np.clip(np.searchsorted(knots, xc) - 1, 0, knots.size - 2)
    a = (xc - knots[k]) / (knots[k + 1] - knots[k])
    F = np.zeros((x.size, knots.size))
    rows = np.arange(x.size)
    F[rows, k] = 1.0 - a
    F[rows, k + 1] += a
    return F


def curve_candidates(adapter, fitted, train: np.ndarray, own: str, channels=()) -> list[Candidate]:
    """The flexible curve (module docstring) of each pot other than ``own`` that reads a joint on a
    chain through one ``own`` reads (:func:`chain_pots`) or is among ``channels``, as Candidates
    made in one sweep; none for a pot whose training readings take fewer than three distinct values
    or whose curve the calibration takes up entirely."""
    sweep = Sweep(fitted, adapter)
    names = sweep.obs.pot_names
    pots = set(chain_pots(sweep.obs, names.index(own))) | {names.index(c) for c in channels if c in names}
    terms, cols = [], []
    for i in sorted(pots - {names.index(own)}):
        j = adapter.pot_names.index(names[i])
        x = np.asarray(fitted.pots[:, j], float)
        seen = x[train & np.isfinite(x)]
        knots = np.unique(np.quantile(seen, np.linspace(0.0, 1.0, CURVE_KNOTS))) if seen.size else seen
        if knots.size < 3:
            continue
        params = tuple(Parameter(f"f{k}") for k in range(knots.size))
        terms.append(Term("unexplained", names[i], params, None, {"knots": [float(v) for v in knots]}))
        cols.append(Columns(partial(pot_block, j=j, f=hat_basis(x, knots)), span=j, projected=True))
    if not cols:
        return []
    made = sweep.channels(cols)
    return [Candidate(t, c) for t, c in zip(terms, made, strict=True) if c is not None]


def chain_pots(obs, own: int) -> list[int]:
    """The pots (mapped order) that read a joint on a chain through one pot ``own`` reads (that
    joint, an ancestor or a descendant of it): those whose readings the tracking of q trades with
    own's. None for a pot that reads no joint directly (a linear pot)."""
    anc = obs.kin._anc[1:]  # (n, n): joint k is joint j or one of its ancestors
    related = anc | anc.T
    A = np.asarray(obs.A) != 0
    if not A[own].any():
        return []
    near = related[:, A[own]].any(axis=1)
    return [i for i in range(A.shape[0]) if i != own and (A[i] & near).any()]


def pot_block(lin, j: int, f: np.ndarray) -> np.ndarray:
    """A pot term's (or curve's) columns on a block: pot j's projected unit column times
    ∂p̂/∂θ ``f`` (T, k)."""
    return lin.project_pot(j)[..., None] * f[lin.frames][:, None, :]
