"""Joint angles from the pots alone, σp = 0 (thesis eq. 2.2, 2.28), and their derivatives.

With noise-free pots the pot model ``gain · s(q) + bias = p`` (eq. 2.18-2.20) is a constraint
that fixes q. One-pot-one-joint sensors (rotary, encoder) are inverted analytically,
``q_j = (p_j - bias_j) / gain_j`` (eq. 2.2); the joints read only by linear (gimbal, eq.
2.19-2.20) or tendon pots are solved per frame by Gauss-Newton, the "numerical inverse
kinematics" of §2.3.3. The classical calibration (:mod:`.classical`) differentiates this map
with respect to the pot parameters (implicit-function theorem); the held-out predictions of
Table 2.2 use it for every method.

The transmission s(q) and ∂s/∂q go through :class:`diegocal.robot.batch.BatchKinematics`:
the linear pots' ∂L/∂q = uᵀ(J_b − J_a) is the projection of the anchors' Jacobians on the unit
axis u, formed from the joint twists without the dense point Jacobian
(:meth:`~diegocal.robot.batch.BatchKinematics.points_project`), in batches of frames.
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass

import numpy as np

from diegocal.errors import DiegocalError, FitError, NumericalError
from diegocal.robot import PointSet, Robot, anchor_points
from diegocal.robot.batch import BatchKinematics
from diegocal.stac.calibration import Calibration

NONLINEAR_KINDS = ("linear", "tendon")
#: frames per batch of the kinematics (memory and cache size, not results)
BATCH = 2000


@dataclass(frozen=True)
class PotInverse:
    """Joint angles solved from pots with σp = 0 (eq. 2.28) and their derivatives.

    q : (T, n) rad
    dtheta : (T, n, G + B) ∂q/∂(free gains, free biases) of a
        :class:`~diegocal.stac.classical.ThetaLayout` (empty last axis when not asked for)
    """

    q: np.ndarray
    dtheta: np.ndarray


class _Transmission:
    """s(q) and ∂s/∂q of a robot's pots, batched (cached per robot)."""

    def __init__(self, robot: Robot):
        pots = robot.sensors.pots
        self.A = np.zeros((len(pots), robot.n_joints))  # s = A q for rotary/encoder/tendon
        for i, p in enumerate(pots):
            if p.kind in ("rotary", "encoder"):
                self.A[i, robot.joint_index(p.joint)] = 1.0
            for joint, arm in p.moment_arms.items():
                self.A[i, robot.joint_index(joint)] = arm
        self.linear = np.array([i for i, p in enumerate(pots) if p.kind == "linear"], dtype=int)
        self.anchors = anchor_points(robot)
        self.robot = robot
        self.kin = batch_kinematics(robot)

    def __call__(self, q: np.ndarray, rows: np.ndarray | None = None, jacobian: bool = True):
        """s (T, R) and ∂s/∂q (T, R, n) (None unless ``jacobian``) of the pots ``rows`` (R,)
        (default all) at q (T, n)."""
        rows = np.arange(self.A.shape[0]) if rows is None else np.asarray(rows, dtype=int)
        A = self.A[rows]
        s = q @ A.T
        ds = np.broadcast_to(A, (q.shape[0], *A.shape)).copy() if jacobian else None
        lin = np.flatnonzero(np.isin(rows, self.linear))  # positions in rows
        if not len(lin):
            return s, ds
        k = np.searchsorted(self.linear, rows[lin])  # their index among the linear pots
        pts = np.stack([2 * k, 2 * k + 1], axis=1).ravel()
        anchors = PointSet(tuple(self.anchors.links[i] for i in pts), self.anchors.xyz[pts])
        for i in range(0, q.shape[0], BATCH):
            sl = slice(i, i + BATCH)
            if self.kin is None:
                x, J = self.robot.points_jacobian(q[sl], anchors)
            else:
                poses = self.kin.joint_poses(q[sl])
                x = self.kin.points(poses, anchors)
            d = x[:, 1::2] - x[:, 0::2]
            length = np.linalg.norm(d, axis=-1)  # eq. 2.19-2.20: L(q)
            s[sl, lin] = length
            if not jacobian:
                continue
            u = d / length[..., None]
            if self.kin is None:
                ds[sl, lin] = np.einsum("tkc,tkcn->tkn", u, J[:, 1::2] - J[:, 0::2])
            else:  # ∂L/∂q = uᵀ (J_b − J_a): the anchors' Jacobians projected on ∓u
                f = np.stack([-u, u], axis=2).reshape(x.shape)
                proj = self.kin.points_project(poses, x, anchors.links, f)
                ds[sl, lin] = proj[:, 0::2] + proj[:, 1::2]
        return s, ds


_CACHE: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
_KIN: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def batch_kinematics(robot: Robot):
    """The frame-vectorised kinematics of ``robot`` (cached), or None for joint types it lacks
    (then Robot's per-frame Pinocchio loop: the same numbers, ~10-50x slower)."""
    if robot not in _KIN:
        try:
            _KIN[robot] = BatchKinematics(robot)
        except DiegocalError:
            _KIN[robot] = None
    return _KIN[robot]


def _transmission(robot: Robot) -> _Transmission:
    if robot not in _CACHE:
        _CACHE[robot] = _Transmission(robot)
    return _CACHE[robot]


def transmission_jacobian(robot: Robot, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """s(q) (T, P) and ∂s/∂q (T, P, n) of every pot (eq. 2.18-2.20, 2.22); as
    :func:`diegocal.robot.pot_transmission_jacobian`, batched."""
    return _transmission(robot)(robot.check_q(q))


def nonlinear_pots(robot: Robot) -> tuple[str, ...]:
    """Names of the pots that are not one-pot-one-joint (linear on gimbals, tendons)."""
    return tuple(p.name for p in robot.sensors.pots if p.kind in NONLINEAR_KINDS)


def _direct(robot: Robot) -> dict:
    """Joint index -> the rotary/encoder pot that reads it (the first one of a joint wins)."""
    direct = {}
    for i, p in enumerate(robot.sensors.pots):
        if p.kind in ("rotary", "encoder"):
            direct.setdefault(robot.joint_index(p.joint), i)
    return direct


def joint_angles_from_pots(
    robot: Robot,
    cal: Calibration,
    pots: np.ndarray,
    q0=None,
    layout=None,
    max_steps: int = 30,
) -> PotInverse:
    """Solve ``gain · s(q) + bias = p`` for q in every frame (thesis eq. 2.2, 2.28).

    Rotary and encoder pots are inverted analytically; the remaining joints are solved by
    Gauss-Newton from the linear/tendon pots (eq. 2.19-2.20), starting at ``q0`` (T, n) or the
    robot's neutral pose. Used both for fitting and for predicting markers from pots.

    Parameters
    ----------
    pots : (T, P) readings, V, in sensors.yaml order
    layout : the free parameters to differentiate with respect to (None: no derivatives; see
        :func:`angle_derivatives`)
    """
    T, n = pots.shape[0], robot.n_joints
    gain, bias = np.asarray(cal.gain, float), np.asarray(cal.bias, float)
    q = np.tile(robot.neutral(), (T, 1)) if q0 is None else np.array(q0, dtype=float)
    direct = _direct(robot)
    unknown = np.array([j for j in range(n) if j not in direct], dtype=int)
    for j, i in direct.items():
        q[:, j] = (pots[:, i] - bias[i]) / gain[i]  # eq. 2.2
    nl = np.array([i for i, p in enumerate(robot.sensors.pots) if p.kind in NONLINEAR_KINDS], dtype=int)
    if len(unknown):
        _check_coverage(robot, unknown, nl)
        q = _gauss_newton(robot, q, unknown, nl, gain, bias, pots, max_steps)
    if layout is None:
        return PotInverse(q, np.zeros((T, n, 0)))
    return PotInverse(q, angle_derivatives(robot, cal, q, layout))


def angle_derivatives(robot: Robot, cal: Calibration, q: np.ndarray, layout) -> np.ndarray:
    """∂q/∂(free gains, free biases) (T, n, G + B) of the pot inverse at its solution q (T, n).

    Directly read joints: ∂q_j/∂gain = −q_j / gain, ∂q_j/∂bias = −1 / gain (eq. 2.2). The
    others by the implicit-function theorem on r(q, θ) = gain · s(q) + bias − p = 0 over the
    linear/tendon pots.
    """
    T, n = q.shape
    gain = np.asarray(cal.gain, float)
    direct = _direct(robot)
    known = np.array(sorted(direct), dtype=int)
    unknown = np.array([j for j in range(n) if j not in direct], dtype=int)
    dtheta = np.zeros((T, n, layout.n_pot_params))
    col_gain = {int(i): c for c, i in enumerate(layout.gain_pots)}
    col_bias = {int(i): len(layout.gain_pots) + c for c, i in enumerate(layout.bias_pots)}
    for j, i in direct.items():
        if i in col_gain:
            dtheta[:, j, col_gain[i]] = -q[:, j] / gain[i]
        if i in col_bias:
            dtheta[:, j, col_bias[i]] = -1.0 / gain[i]
    if len(unknown):
        nl = np.array([i for i, p in enumerate(robot.sensors.pots) if p.kind in NONLINEAR_KINDS], dtype=int)
        s, ds = _transmission(robot)(q, nl)
        G = ds * gain[nl][None, :, None]  # (T, Pnl, n)
        rhs = np.einsum("tpk,tkc->tpc", G[:, :, known], dtheta[:, known])
        for r, i in enumerate(nl):
            if i in col_gain:
                rhs[:, r, col_gain[i]] += s[:, r]
            if i in col_bias:
                rhs[:, r, col_bias[i]] += 1.0
        dtheta[:, unknown] = -np.linalg.pinv(G[:, :, unknown]) @ rhs
    return dtheta


def _check_coverage(robot: Robot, unknown: np.ndarray, nl: np.ndarray) -> None:
    """Every joint without a rotary/encoder pot must move some linear/tendon pot."""
    rng = np.random.default_rng(0)
    lo = np.where(np.isfinite(robot.lower), robot.lower, -1.0)
    hi = np.where(np.isfinite(robot.upper), robot.upper, 1.0)
    probe = lo + (hi - lo) * rng.uniform(0.3, 0.7, size=(2, robot.n_joints))
    _, ds = _transmission(robot)(probe, nl)
    seen = np.abs(ds[:, :, unknown]).max(axis=(0, 1)) if len(nl) else np.zeros(len(unknown))
    blind = [robot.joint_names[j] for j, v in zip(unknown, seen, strict=True) if v < 1e-12]
    if blind:
        raise FitError(f"classical calibration needs every joint read by a pot; no pot reads: {', '.join(blind)}")
    if len(nl) < len(unknown):
        raise FitError(f"classical calibration: {len(unknown)} joints depend on only {len(nl)} linear/tendon pots")


def _gauss_newton(robot, q, unknown, nl, gain, bias, pots, max_steps) -> np.ndarray:
    """Per-frame Gauss-Newton on the nl-pot constraints for the joints in ``unknown``.

    Frames leave the iteration once their step is below 1e-9 rad; a frame whose solution lies
    past a joint limit (noise near a singular gimbal pose) stops at the limit after max_steps.
    """
    q = q.copy()
    lo, hi = robot.lower[unknown], robot.upper[unknown]
    active = np.arange(q.shape[0])
    trans = _transmission(robot)
    for _ in range(max_steps):
        s, ds = trans(q[active], nl)
        r = gain[nl] * s + bias[nl] - pots[active][:, nl]
        G = ds[:, :, unknown] * gain[nl][None, :, None]
        if G.shape[1] == G.shape[2]:  # as many pots as joints (gimbals): Newton
            try:
                step = np.linalg.solve(G, r[..., None])[..., 0]
            except np.linalg.LinAlgError:
                step = np.einsum("tkp,tp->tk", np.linalg.pinv(G), r)
        else:  # more pots than joints: Gauss-Newton
            step = np.einsum("tkp,tp->tk", np.linalg.pinv(G), r)
        dq = np.clip(-step, -0.3, 0.3)  # damped: the gimbal lengths are far from linear
        new = np.clip(q[np.ix_(active, unknown)] + dq, lo, hi)
        if not np.isfinite(new).all():
            raise NumericalError("solving linear/tendon pots for joint angles failed (non-finite); check the gains")
        moved = np.abs(new - q[np.ix_(active, unknown)]).max(axis=1)
        q[np.ix_(active, unknown)] = new
        active = active[moved > 1e-9]
        if not len(active):
            break
    return q
