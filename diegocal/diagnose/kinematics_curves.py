"""Flexible models of the pots (issue #31, item 1: a wrong name is worse than ``unexplained``).
A pot read through a gear with runout, or one that picks up another pot's signal, is misread by
STAC as a q error: tracked jointly with the pots that read the same chain, the error moves to its
neighbours, where a named cause of theirs (a backlash on the next pot) explains part of it. The
engine then asks whether a flexible model of a neighbour explains more
(:meth:`KinematicsAdapter.spill_candidates <diegocal.diagnose.kinematics.KinematicsAdapter.spill_candidates>`):
its *curve*, a piecewise-linear function of its model reading with CURVE_KNOTS knots at the
quantiles of its training readings, its *mixing row*, a linear function of the angles of the
joints on its chain, and its *lag*, the reading through a first-order filter (an RC on the pot's
line: an error in proportion to its speed, which a dead band's column, the direction of motion,
takes up in part; offered for a pot term's own pot too: a user trial's 15-30 ms lag on a Baxter
elbow pot was named ``backlash``). A pot term's own pot also has its *load curve*, an error in
proportion to the gravity torque on its joint, scaled linearly along its reading (a belt or
tendon stretching under the joint's load; a user trial's 2 % belt stretch on a G1 elbow was named
``sensor_nonlinearity``, whose u², u³ take up the part that follows the elbow's own angle).
Each is linearised like any pot term (projected out of q and of the pots' gains and biases,
:class:`~diegocal.diagnose.kinematics_sweep.Sweep`); its term is ``unexplained``: a shape, never
a cause.
"""

from __future__ import annotations

from functools import partial

import numpy as np
import pinocchio as pin
from scipy.signal import savgol_filter

from diegocal.diagnose.kinematics_sweep import Columns, Sweep
from diegocal.diagnose.stats import quantile_edges
from diegocal.diagnose.types import Candidate
from diegocal.terms import Parameter, Term

#: Knots of a pot's flexible curve: enough for a runout of six periods over the visited range.
CURVE_KNOTS = 13
#: Samples of the centred quadratic (Savitzky-Golay) smoother a reading's rate is the slope of.
RATE_SMOOTH = 11


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


def curve_candidates(sweep: Sweep, fitted, train: np.ndarray, term: Term, channels=()) -> list[Candidate]:
    """The flexible models (module docstring) of each pot near ``term`` (:func:`neighbour_pots`)
    or among ``channels``, as Candidates made in one sweep: its lag, its curve (none when its
    training readings take fewer than three distinct values) and its mixing row (none for a pot on
    no chain); of a pot term's own pot its lag and its load curve (none for a joint gravity does
    not load); none that the calibration takes up entirely.
    ``sweep``: the linearisation at ``fitted`` (the round's, whose blocks are kept)."""
    adapter, obs, names = sweep.adapter, sweep.obs, sweep.obs.pot_names
    pots = set(neighbour_pots(obs, adapter.robot, term)) | {names.index(c) for c in channels if c in names}
    terms, cols = [], []
    own = _own(obs, term)
    for i in sorted(pots | ({own} if own is not None else set())):
        j = adapter.pot_names.index(names[i])
        shapes = [_lag(names[i], adapter.time, fitted.pots[:, j])]  # its own pot too: read through a filter
        if i != own:
            shapes += [_curve(names[i], fitted.pots[:, j], train), _mixing(obs, i, fitted.q, train)]
        else:
            shapes += [_load(obs, i, fitted.q, fitted.pots[:, j], train)]
        for made, f in shapes:
            if made is not None:
                terms.append(made)
                cols.append(Columns(partial(pot_block, j=j, f=f), span=j, projected=True))
    if not cols:
        return []
    made = sweep.channels(cols)
    return [Candidate(t, c) for t, c in zip(terms, made, strict=True) if c is not None]


def reading_rate(time: np.ndarray, x: np.ndarray) -> np.ndarray:
    """(T,) the rate of a reading x (T,) at ``time`` (T,) s, in its unit per second: the derivative
    of a :data:`RATE_SMOOTH`-sample centred quadratic at the median sample step (a finite
    difference where the log is shorter); x not finite: zero."""
    x = np.nan_to_num(np.asarray(x, float))
    dt = float(np.median(np.diff(time))) if len(time) > 1 else 1.0
    if x.size < RATE_SMOOTH:
        return np.gradient(x, dt) if x.size > 1 else np.zeros_like(x)
    return savgol_filter(x, RATE_SMOOTH, 2, deriv=1, delta=dt)


def _lag(name: str, time: np.ndarray, x: np.ndarray) -> tuple:
    """(term, ∂p̂/∂θ (T, 1)) of a pot read through a first-order filter of time constant ``lag``
    (s): p = ŷ(t − lag) ≈ ŷ − lag dŷ/dt, ŷ its model reading x (T,) at ``time`` (T,) s."""
    term = Term("unexplained", name, (Parameter("lag", unit="s"),), None, {"model": "first-order lag"})
    return term, -reading_rate(time, x)[:, None]


def _curve(name: str, x: np.ndarray, train: np.ndarray) -> tuple:
    """(term, ∂p̂/∂θ (T, K)) of a pot's curve: hat functions of its model reading ``x`` on knots at
    the quantiles of its training readings; (None, None) for fewer than three distinct knots."""
    x = np.asarray(x, float)
    knots = quantile_edges(x[train], CURVE_KNOTS - 1)
    if knots.size < 3:
        return None, None
    params = tuple(Parameter(f"f{k}") for k in range(knots.size))
    return Term("unexplained", name, params, None, {"knots": [float(v) for v in knots]}), hat_basis(x, knots)


def _mixing(obs, i: int, q: np.ndarray, train: np.ndarray) -> tuple:
    """(term, ∂p̂/∂θ (T, n')) of pot i's mixing row: its reading plus a linear function of the
    angles of the joints on a chain through its own (their training means taken out): another
    pot's signal picked up (crosstalk on a shared ground), a tendon's moment arms off; (None,
    None) for a pot that reads no joint directly."""
    joints = _near_joints(obs, i)
    if not joints.any():
        return None, None
    idx = np.flatnonzero(joints)
    names = [obs.robot.joint_names[k] for k in idx]
    params = tuple(Parameter(f"q.{n}") for n in names)
    f = q[:, idx] - np.nanmean(q[np.asarray(train, bool)][:, idx], axis=0)
    return Term("unexplained", obs.pot_names[i], params, None, {"mixing": names}), np.nan_to_num(f)


def _load(obs, i: int, q: np.ndarray, x: np.ndarray, train: np.ndarray) -> tuple:
    """(term, ∂p̂/∂θ (T, 2)) of pot i's load curve: an error in proportion to the gravity torque
    on the joint it reads (the URDF's inertias at the tracked q), its compliance a linear function
    of the reading ``x``: a belt or tendon that stretches under the joint's load; (None, None) for
    a pot that reads no joint directly or a joint gravity does not load."""
    k = np.flatnonzero(np.asarray(obs.A)[i] != 0)
    model = obs.robot.model
    if k.size != 1 or model.nq != q.shape[1]:
        return None, None
    data = model.createData()
    g = np.array([pin.computeGeneralizedGravity(model, data, qq)[k[0]] for qq in np.nan_to_num(q)])
    if not np.any(g[train]):
        return None, None
    g = g / np.max(np.abs(g[train]))
    u = (x - np.nanmean(x[train])) / max(float(np.nanstd(x[train])), 1e-12)
    params = (Parameter("c0"), Parameter("c1"))
    term = Term("unexplained", obs.pot_names[i], params, None, {"model": "load"})
    return term, np.nan_to_num(np.column_stack([g, g * u]))


def neighbour_pots(obs, robot, term: Term) -> list[int]:
    """The pots (mapped order) whose readings the tracking of q trades with ``term``'s effect: for
    a pot term, the other pots that read a joint on a chain through one its pot reads (that joint,
    an ancestor or a descendant of it; none for a linear pot); for a link offset, those on a chain
    through its joint; for a marker's slip, those that read a joint moving the marker."""
    A = np.asarray(obs.A) != 0
    own = _own(obs, term)
    if term.cause == "link_offset":
        near = _chain(obs, np.arange(A.shape[1]) == robot.joint_index(term.channel))
    elif term.cause == "marker_slip":
        links, _, _ = obs.kin.link_info(obs.marker_links)
        near = obs.kin._anc[links[obs.marker_names.index(term.channel)]]
    elif own is not None:
        near = _near_joints(obs, own)
    else:
        return []
    return [i for i in range(A.shape[0]) if i != own and (A[i] & near).any()]


def _own(obs, term: Term) -> int | None:
    """The pot (mapped order) a pot term acts on; None for a term on a joint or a marker."""
    on_joint_or_marker = term.cause in ("link_offset", "marker_slip")
    return None if on_joint_or_marker or term.channel not in obs.pot_names else obs.pot_names.index(term.channel)


def _near_joints(obs, i: int) -> np.ndarray:
    """(n,) bool: the joints on a chain through a joint pot i reads (none for a linear pot)."""
    return _chain(obs, np.asarray(obs.A)[i] != 0)


def _chain(obs, joints: np.ndarray) -> np.ndarray:
    """(n,) bool: the joints on a chain through one of ``joints`` (n,) bool: it, an ancestor or a
    descendant of it."""
    anc = obs.kin._anc[1:]  # (n, n): joint k is joint j or one of its ancestors
    return (anc | anc.T)[:, joints].any(axis=1)


def pot_block(lin, j: int, f: np.ndarray) -> np.ndarray:
    """A pot term's (or curve's) columns on a block: pot j's projected unit column times
    ∂p̂/∂θ ``f`` (T, k)."""
    return lin.project_pot(j)[..., None] * f[lin.frames][:, None, :]
