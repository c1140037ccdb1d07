"""Classical regression-based kinematic calibration, STAC's σp = 0 limit (thesis §2.2.1, §2.4.2).

With noise-free pots the pot term of the likelihood (eq. 2.21) becomes a constraint
(eq. 2.28). For one-pot-one-joint sensors (rotary, encoder) the constraint is solved
analytically, ``q_j = (p_j - bias_j) / gain_j`` (eq. 2.2), and the joint angles disappear
from the problem: the parameters θ = (gains, biases, R, T0, d_1:M) minimise the marker error
alone (eq. 2.29 = eq. 2.4),

.. math:: \\min_\\theta \\sum_{t,m} \\| \\hat x_{mt}(\\theta, q_t(p_t, \\theta)) - x_{mt} \\|^2 ,

solved by :func:`scipy.optimize.least_squares` with an analytic Jacobian (chain rule through
eq. 2.23's ∂x̂/∂q). Linear (gimbal, eq. 2.19-2.20) and tendon pots are the case the thesis says
classical methods cannot handle: by default :func:`calibrate_classical` refuses them by name.
Two explicit alternatives (``nonlinear_pots=``):

``"constrain"``
    eq. 2.28 taken literally: the joints those pots span are solved numerically from the
    constraint ``gain · s(q) + bias = p`` in every frame (Gauss-Newton, the "numerical inverse
    kinematics" of §2.3.3), their gains/biases are estimated too, and the Jacobian goes
    through the implicit-function theorem. This is what Table 2.2's "stac-σp = 0" row of the
    humanoid needs (its 8 gimbal pots are "Tendon" in that table and were calibrated).
``"nominal"``
    those joints are solved from the pots with their nominal gains/biases and held there;
    their pots are not calibrated (standard errors NaN).

The mocap frame (R, T0) is initialised by Procrustes (eq. 2.13-2.16) on the nominal joint
angles, as a classical method would; every other parameter starts at its nominal value.
"""

from __future__ import annotations

import time
import weakref
from dataclasses import dataclass, replace

import numpy as np
import pinocchio as pin
from scipy import sparse
from scipy.optimize import least_squares

from diegocal.errors import DiegocalError, FitError, NumericalError
from diegocal.io import Log
from diegocal.robot import PointSet, Robot, anchor_points, marker_points
from diegocal.stac.calibration import Calibration, FitInfo
from diegocal.stac.result import IterationRecord, StacOptions, StacResult

NONLINEAR_KINDS = ("linear", "tendon")
_MODES = ("refuse", "constrain", "nominal")


# ---------------------------------------------------------------------------------- parameters
@dataclass(frozen=True)
class ThetaLayout:
    """Where each free sensor parameter sits in the packed vector θ (thesis eq. 2.10).

    Order: free gains, free biases, mocap rotation vector r (R = exp([r]×), 3), T0 (3),
    marker positions d_1:M (3M, metres in link frames).

    gain_pots, bias_pots : pot indices whose gain / bias is estimated
    n_markers : M
    """

    gain_pots: np.ndarray
    bias_pots: np.ndarray
    n_markers: int

    @classmethod
    def for_robot(cls, robot: Robot, frozen=()) -> ThetaLayout:
        """Every gain but encoders' (fixed at 1) and every bias, except pots named in ``frozen``."""
        pots = robot.sensors.pots
        gain = [i for i, p in enumerate(pots) if p.kind != "encoder" and p.name not in frozen]
        bias = [i for i, p in enumerate(pots) if p.name not in frozen]
        return cls(np.array(gain, dtype=int), np.array(bias, dtype=int), len(robot.sensors.markers))

    @property
    def n_pot_params(self) -> int:
        return len(self.gain_pots) + len(self.bias_pots)

    @property
    def rot(self) -> slice:
        return slice(self.n_pot_params, self.n_pot_params + 3)

    @property
    def trans(self) -> slice:
        return slice(self.n_pot_params + 3, self.n_pot_params + 6)

    @property
    def xyz(self) -> slice:
        return slice(self.n_pot_params + 6, self.size)

    @property
    def size(self) -> int:
        return self.n_pot_params + 6 + 3 * self.n_markers

    def pack(self, cal: Calibration) -> np.ndarray:
        rot = pin.log3(np.asarray(cal.mocap_R, float))
        return np.concatenate(
            [
                cal.gain[self.gain_pots],
                cal.bias[self.bias_pots],
                rot,
                cal.mocap_T,
                cal.marker_xyz.ravel(),
            ]
        )

    def unpack(self, x: np.ndarray, template: Calibration) -> Calibration:
        gain, bias = template.gain.copy(), template.bias.copy()
        ng = len(self.gain_pots)
        gain[self.gain_pots] = x[:ng]
        bias[self.bias_pots] = x[ng : self.n_pot_params]
        return replace(
            template,
            gain=gain,
            bias=bias,
            mocap_R=pin.exp3(x[self.rot]),
            mocap_T=x[self.trans].copy(),
            marker_xyz=x[self.xyz].reshape(-1, 3).copy(),
        )

    def standard_errors(self, se: np.ndarray, template: Calibration) -> Calibration:
        """Put packed standard errors (NaN = not estimated or unidentifiable) into a Calibration."""
        P = len(template.pot_names)
        gse, bse = np.full(P, np.nan), np.full(P, np.nan)
        ng = len(self.gain_pots)
        gse[self.gain_pots] = se[:ng]
        bse[self.bias_pots] = se[ng : self.n_pot_params]
        return replace(
            template, gain_se=gse, bias_se=bse, marker_xyz_se=se[self.xyz].reshape(-1, 3)
        )


# ---------------------------------------------------------------------------------- kinematics
_BATCH: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def _batch(robot: Robot):
    """STAC's frame-vectorised kinematics for ``robot`` (cached), or None where unavailable.

    It is tested to equal Robot.points/points_jacobian; Robot's per-frame Pinocchio loop is
    the fallback (same numbers, ~10-50× slower at thesis size).
    """
    if robot not in _BATCH:
        try:
            from diegocal.robot.batch import BatchKinematics

            _BATCH[robot] = BatchKinematics(robot)
        except (ImportError, DiegocalError):
            _BATCH[robot] = None
    return _BATCH[robot]


def points_jacobian(robot: Robot, q: np.ndarray, points: PointSet):
    """Points (T, N, 3) m and ∂/∂q (T, N, 3, n) in the base frame (thesis eq. 2.23)."""
    bk = _batch(robot)
    if bk is None:
        return robot.points_jacobian(q, points)
    return bk.points_jacobian(bk.joint_poses(q), points)


def link_rotations(robot: Robot, q: np.ndarray, links) -> np.ndarray:
    """Rotation of each link in the base frame: (T, L, 3, 3)."""
    bk = _batch(robot)
    if bk is None:
        return robot.link_poses(q, links)[0]
    return bk.link_poses(bk.joint_poses(q), links)[0]


def transmission_jacobian(robot: Robot, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """s(q) (T, P) and ∂s/∂q (T, P, n) of every pot (eq. 2.18-2.20, 2.22); as
    :func:`diegocal.robot.pot_transmission_jacobian`, with the batched anchor kinematics."""
    q = robot.check_q(q)
    P, n = len(robot.sensors.pots), robot.n_joints
    A = np.zeros((P, n))
    for i, p in enumerate(robot.sensors.pots):
        if p.kind in ("rotary", "encoder"):
            A[i, robot.joint_index(p.joint)] = 1.0
        for joint, arm in p.moment_arms.items():
            A[i, robot.joint_index(joint)] = arm
    s, ds = q @ A.T, np.broadcast_to(A, (q.shape[0], P, n)).copy()
    linear = [i for i, p in enumerate(robot.sensors.pots) if p.kind == "linear"]
    if linear:
        x, J = points_jacobian(robot, q, anchor_points(robot))
        d = x[:, 1::2] - x[:, 0::2]
        length = np.linalg.norm(d, axis=-1)  # eq. 2.19-2.20: L(q)
        s[:, linear] = length
        ds[:, linear] = np.einsum("tkc,tkcn->tkn", d / length[..., None], J[:, 1::2] - J[:, 0::2])
    return s, ds


# ---------------------------------------------------------------------------------- markers
@dataclass(frozen=True)
class MarkerModel:
    """Predicted markers and Jacobians at joint angles ``q`` (T, n), thesis eq. 2.11-2.12, 2.23.

    x : (T, M, 3) predictions in the mocap frame, m
    dq : (T, M, 3, n) ∂x̂/∂q, m/rad (eq. 2.23)
    drot : (T, M, 3, 3) ∂x̂/∂r for R = exp([r]×): -R [x^b]× J_r(r)
    dxyz : (T, M, 3, 3) ∂x̂_m/∂d_m = R · R_link(q) (the trans block ∂x̂/∂T0 is the identity)
    """

    x: np.ndarray
    dq: np.ndarray
    drot: np.ndarray
    dxyz: np.ndarray


def marker_model(robot: Robot, q: np.ndarray, cal: Calibration) -> MarkerModel:
    """Evaluate :class:`MarkerModel` for calibration ``cal``; ``q`` (T, n) rad."""
    R = np.asarray(cal.mocap_R, float)
    xb, dq = points_jacobian(robot, q, marker_points(robot, cal.marker_xyz))
    dq = np.einsum("ij,tmjn->tmin", R, dq)  # eq. 2.23 in the mocap frame
    x = xb @ R.T + cal.mocap_T
    Jr = pin.Jexp3(pin.log3(R))
    skew = np.zeros(xb.shape + (3,))
    skew[..., 0, 1], skew[..., 0, 2], skew[..., 1, 2] = -xb[..., 2], xb[..., 1], -xb[..., 0]
    skew[..., 1, 0], skew[..., 2, 0], skew[..., 2, 1] = xb[..., 2], -xb[..., 1], xb[..., 0]
    drot = -np.einsum("ij,tmjk,kl->tmil", R, skew, Jr)
    rot_link = link_rotations(robot, q, cal.marker_links)
    dxyz = np.einsum("ij,tmjk->tmik", R, rot_link)
    return MarkerModel(x, dq, drot, dxyz)


def kabsch(base: np.ndarray, mocap: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rigid transform with mocap ≈ R base + T from (N, 3) point pairs (thesis eq. 2.13-2.16).

    The thesis's eq. 2.15 guard ``sign(det Σ)`` is not the reflection guard Kabsch's method
    needs; this uses the standard ``R = V diag(1, 1, det(V Uᵀ)) Uᵀ``.
    """
    ok = np.isfinite(base).all(axis=1) & np.isfinite(mocap).all(axis=1)
    a, b = base[ok], mocap[ok]
    if len(a) < 3:
        raise FitError("too few visible markers to place the mocap frame (need 3 or more)")
    ca, cb = a.mean(axis=0), b.mean(axis=0)  # eq. 2.13
    U, _, Vt = np.linalg.svd((a - ca).T @ (b - cb))  # eq. 2.14
    V = Vt.T
    R = V @ np.diag([1.0, 1.0, np.sign(np.linalg.det(V @ U.T))]) @ U.T
    return R, cb - R @ ca  # eq. 2.16


# ---------------------------------------------------------------------------------- pots -> q
@dataclass(frozen=True)
class PotInverse:
    """Joint angles solved from pots with σp = 0 (eq. 2.28) and their derivatives.

    q : (T, n) rad
    dtheta : (T, n, G + B) ∂q/∂(free gains, free biases) of a :class:`ThetaLayout`
    """

    q: np.ndarray
    dtheta: np.ndarray


def nonlinear_pots(robot: Robot) -> tuple[str, ...]:
    """Names of the pots that are not one-pot-one-joint (linear on gimbals, tendons)."""
    return tuple(p.name for p in robot.sensors.pots if p.kind in NONLINEAR_KINDS)


def joint_angles_from_pots(
    robot: Robot,
    cal: Calibration,
    pots: np.ndarray,
    q0=None,
    layout: ThetaLayout | None = None,
    max_steps: int = 30,
) -> PotInverse:
    """Solve ``gain · s(q) + bias = p`` for q in every frame (thesis eq. 2.2, 2.28).

    Rotary and encoder pots are inverted analytically; the remaining joints are solved by
    Gauss-Newton from the linear/tendon pots (eq. 2.19-2.20), starting at ``q0`` (T, n) or the
    robot's neutral pose. Used both for fitting and for predicting markers from pots.

    Parameters
    ----------
    pots : (T, P) readings, V, in sensors.yaml order
    layout : the free parameters to differentiate with respect to (None: no derivatives)
    """
    pot_specs = robot.sensors.pots
    T, n = pots.shape[0], robot.n_joints
    gain, bias = np.asarray(cal.gain, float), np.asarray(cal.bias, float)
    q = np.tile(robot.neutral(), (T, 1)) if q0 is None else np.array(q0, dtype=float)
    direct = {}
    for i, p in enumerate(pot_specs):
        if p.kind in ("rotary", "encoder"):
            direct.setdefault(robot.joint_index(p.joint), i)  # first pot of a joint wins
    known = np.array(sorted(direct), dtype=int)
    unknown = np.array([j for j in range(n) if j not in direct], dtype=int)
    for j, i in direct.items():
        q[:, j] = (pots[:, i] - bias[i]) / gain[i]  # eq. 2.2
    nl = np.array([i for i, p in enumerate(pot_specs) if p.kind in NONLINEAR_KINDS], dtype=int)
    if len(unknown):
        _check_coverage(robot, unknown, nl)
        q = _gauss_newton(robot, q, unknown, nl, gain, bias, pots, max_steps)
    if layout is None:
        return PotInverse(q, np.zeros((T, n, 0)))
    dtheta = np.zeros((T, n, layout.n_pot_params))
    col_gain = {int(i): c for c, i in enumerate(layout.gain_pots)}
    col_bias = {int(i): len(layout.gain_pots) + c for c, i in enumerate(layout.bias_pots)}
    for j, i in direct.items():
        if i in col_gain:
            dtheta[:, j, col_gain[i]] = -q[:, j] / gain[i]
        if i in col_bias:
            dtheta[:, j, col_bias[i]] = -1.0 / gain[i]
    if len(unknown):
        # implicit function theorem on r(q, θ) = gain·s(q) + bias − p = 0 for the nl pots
        s, ds = transmission_jacobian(robot, q)
        G = ds[:, nl] * gain[nl][None, :, None]  # (T, Pnl, n)
        rhs = np.einsum("tpk,tkc->tpc", G[:, :, known], dtheta[:, known])
        for r, i in enumerate(nl):
            if i in col_gain:
                rhs[:, r, col_gain[i]] += s[:, i]
            if i in col_bias:
                rhs[:, r, col_bias[i]] += 1.0
        dtheta[:, unknown] = -np.linalg.pinv(G[:, :, unknown]) @ rhs
    return PotInverse(q, dtheta)


def _check_coverage(robot: Robot, unknown: np.ndarray, nl: np.ndarray) -> None:
    """Every joint without a rotary/encoder pot must move some linear/tendon pot."""
    rng = np.random.default_rng(0)
    lo = np.where(np.isfinite(robot.lower), robot.lower, -1.0)
    hi = np.where(np.isfinite(robot.upper), robot.upper, 1.0)
    probe = lo + (hi - lo) * rng.uniform(0.3, 0.7, size=(2, robot.n_joints))
    _, ds = transmission_jacobian(robot, probe)
    seen = np.abs(ds[:, nl][:, :, unknown]).max(axis=(0, 1)) if len(nl) else np.zeros(len(unknown))
    blind = [robot.joint_names[j] for j, v in zip(unknown, seen, strict=True) if v < 1e-12]
    if blind:
        raise FitError(
            "classical calibration needs every joint read by a pot; "
            f"no pot reads: {', '.join(blind)}"
        )
    if len(nl) < len(unknown):
        raise FitError(
            f"classical calibration: {len(unknown)} joints depend on only "
            f"{len(nl)} linear/tendon pots"
        )


def _gauss_newton(robot, q, unknown, nl, gain, bias, pots, max_steps) -> np.ndarray:
    """Per-frame Gauss-Newton on the nl-pot constraints for the joints in ``unknown``.

    Frames leave the iteration once their step is below 1e-9 rad; a frame whose solution lies
    past a joint limit (noise near a singular gimbal pose) stops at the limit after max_steps.
    """
    q = q.copy()
    lo, hi = robot.lower[unknown], robot.upper[unknown]
    active = np.arange(q.shape[0])
    for _ in range(max_steps):
        s, ds = transmission_jacobian(robot, q[active])
        r = gain[nl] * s[:, nl] + bias[nl] - pots[active][:, nl]
        G = ds[:, nl][:, :, unknown] * gain[nl][None, :, None]
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
            raise NumericalError(
                "solving linear/tendon pots for joint angles failed (non-finite); check the gains"
            )
        moved = np.abs(new - q[np.ix_(active, unknown)]).max(axis=1)
        q[np.ix_(active, unknown)] = new
        active = active[moved > 1e-9]
        if not len(active):
            break
    return q


# ---------------------------------------------------------------------------------- the fit
def calibrate_classical(
    log: Log,
    robot: Robot,
    options: StacOptions | None = None,
    *,
    nonlinear: str = "refuse",
    q0=None,
) -> StacResult:
    """Classical σp = 0 calibration: minimise eq. 2.29 over θ with q = q(p, θ) (thesis §2.4.2).

    Parameters
    ----------
    log : Log with ``pots`` (T, P) V and ``markers`` (T, M, 3) m (NaN = occluded); never its truth
    robot : Robot
    options : StacOptions; uses ``max_iterations`` (4× of it bounds the function evaluations),
        ``loss`` ('huber': a second pass with the Huber loss at ``huber_scale`` robust sigmas)
    nonlinear : 'refuse' (default) | 'constrain' | 'nominal': what to do with linear/tendon pots
        (see the module docstring)
    q0 : optional (n,) or (T, n) starting joint angles for the joints solved numerically

    Returns
    -------
    StacResult with method 'classical', standard errors from the Gauss-Newton covariance
    (NaN for parameters the markers cannot identify, e.g. the bias of the last joint before a
    marker-carrying leaf link, which trades off exactly against those markers' positions),
    ``sigma_pots`` = 0 by assumption and ``sigma_markers`` the residual RMS per coordinate;
    ``q`` (T, n) are the joint angles implied by the fitted pots.
    """
    options = options or StacOptions()
    if nonlinear not in _MODES:
        raise FitError(f"nonlinear={nonlinear!r}: expected one of {', '.join(_MODES)}")
    hard = nonlinear_pots(robot)
    if hard and nonlinear == "refuse":
        raise FitError(
            f"classical calibration cannot handle linear/tendon pots: {', '.join(hard)}"
            "; use --method stac (or nonlinear='constrain': σp = 0 constraints)"
        )
    pots, markers = read_streams(log, robot, "classical calibration")
    started = time.perf_counter()
    nominal = replace(Calibration.nominal(robot), method="classical")
    layout = ThetaLayout.for_robot(robot, frozen=hard if nonlinear == "nominal" else ())
    if q0 is not None:
        q0 = np.broadcast_to(np.asarray(q0, float), (pots.shape[0], robot.n_joints))
    inv = joint_angles_from_pots(robot, nominal, pots, q0=q0)
    xb = points_jacobian(robot, inv.q, marker_points(robot, nominal.marker_xyz))[0]
    R0, T0 = kabsch(xb.reshape(-1, 3), markers.reshape(-1, 3))  # eq. 2.13-2.16 seed
    seed = replace(nominal, mocap_R=R0, mocap_T=T0)
    problem = _Problem(robot, layout, seed, pots, markers, inv.q)
    res = problem.solve(layout.pack(seed), options, "linear", 1.0)
    if options.loss == "huber":
        # the Huber corner at huber_scale robust sigmas (MAD of the least-squares residuals)
        scale = options.huber_scale * max(1.4826 * np.median(np.abs(res.fun)), 1e-9)
        res = problem.solve(res.x, options, "huber", scale)
    if not np.isfinite(res.x).all():
        raise NumericalError(
            "classical calibration diverged (non-finite parameters); check the nominal seed"
        )
    fitted = layout.unpack(res.x, seed)
    inv = problem.inverse(res.x)
    dof = max(res.fun.size - np.linalg.matrix_rank(problem.normal_matrix(res.x)), 1)
    sigma = float(np.sqrt(np.sum(res.fun**2) / dof))
    se = packed_standard_errors(problem.normal_matrix(res.x), sigma)
    seconds = time.perf_counter() - started
    fitted = layout.standard_errors(se, fitted)
    fitted = replace(
        fitted,
        sigma_pots=0.0,
        sigma_markers=sigma,
        fit=FitInfo(float(res.cost), int(res.nfev), bool(res.status > 0), seconds),
    )
    record = IterationRecord(int(res.nfev), float(res.cost), 0.0, sigma, seconds)
    return StacResult(fitted, inv.q, (record,))


def read_streams(log: Log, robot: Robot, who: str) -> tuple[np.ndarray, np.ndarray]:
    """The robot's pots (T, P) V and markers (T, M, 3) m from ``log``, in sensors.yaml order."""
    pots = log.stream("pots", needed_by=who).select(robot.sensors.pot_names).data
    markers = log.stream("markers", needed_by=who).select(robot.sensors.marker_names).data
    if pots.shape[0] < 2:
        raise FitError(f"{who} needs at least 2 samples, the log has {pots.shape[0]}")
    if not np.isfinite(markers).any():
        raise FitError(f"{who}: every marker sample is NaN (occluded)")
    return pots, markers


def packed_standard_errors(JtJ: np.ndarray, sigma: float, tol: float = 1e-10) -> np.ndarray:
    """sqrt(diag(σ² (JᵀJ)⁺)), NaN for parameters with a component in JᵀJ's null space.

    JᵀJ is equilibrated by its diagonal first so that the rank decision does not depend on units.
    """
    d = np.sqrt(np.clip(np.diag(JtJ), 0.0, None))
    dead = d <= 0.0
    d[dead] = 1.0
    A = JtJ / np.outer(d, d)
    w, V = np.linalg.eigh(A)
    keep = w > tol * max(w.max(), 1e-300)
    cov = (V[:, keep] / w[keep]) @ V[:, keep].T / np.outer(d, d)
    se = sigma * np.sqrt(np.clip(np.diag(cov), 0.0, None))
    in_null = (V[:, ~keep] ** 2).sum(axis=1) > 1e-6
    se[in_null | dead] = np.nan
    return se


class _Problem:
    """Residuals (visible marker coordinates, m) and their Jacobian for least_squares, cached."""

    def __init__(self, robot, layout, template, pots, markers, q_start):
        self.robot, self.layout, self.template = robot, layout, template
        self.pots, self.markers = pots, markers
        self.visible = np.isfinite(markers).reshape(-1)
        self.q_warm = q_start
        self._key = None
        T, M = markers.shape[:2]
        self.dense = self.visible.sum() * layout.size <= 4_000_000
        # sparsity of the marker-position block: row (t, m, c) -> column xyz.start + 3m + k
        rows = np.arange(T * M * 3).reshape(T, M, 3, 1).repeat(3, axis=3)
        cols = (
            layout.xyz.start
            + 3 * np.arange(M)[None, :, None, None]
            + np.arange(3)[None, None, None, :]
        )
        self._xyz_rows, self._xyz_cols = rows.ravel(), np.broadcast_to(cols, rows.shape).ravel()

    def inverse(self, x) -> PotInverse:
        self._evaluate(x)
        return self._inv

    def _evaluate(self, x):
        key = x.tobytes()
        if key == self._key:
            return
        cal = self.layout.unpack(x, self.template)
        inv = joint_angles_from_pots(self.robot, cal, self.pots, q0=self.q_warm, layout=self.layout)
        self.q_warm = inv.q
        self._inv, self._cal = inv, cal
        self._model = marker_model(self.robot, inv.q, cal)
        self._key = key

    def residual(self, x) -> np.ndarray:
        self._evaluate(x)
        return (self._model.x - self.markers).reshape(-1)[self.visible]

    def jacobian(self, x):
        self._evaluate(x)
        mm, lay = self._model, self.layout
        T, M = self.markers.shape[:2]
        head = np.concatenate(
            [
                np.einsum("tmcn,tnk->tmck", mm.dq, self._inv.dtheta),  # pot params through q(p, θ)
                mm.drot,
                np.broadcast_to(np.eye(3), (T, M, 3, 3)),
            ],
            axis=3,
        ).reshape(T * M * 3, -1)
        vals = mm.dxyz.reshape(-1)
        if self.dense:
            J = np.zeros((T * M * 3, lay.size))
            J[:, : lay.xyz.start] = head
            J[self._xyz_rows, self._xyz_cols] = vals
            return J[self.visible]
        r, c = np.nonzero(head)
        rows = np.concatenate([r, self._xyz_rows])
        cols = np.concatenate([c, self._xyz_cols])
        J = sparse.csr_matrix(
            (np.concatenate([head[r, c], vals]), (rows, cols)), shape=(T * M * 3, lay.size)
        )
        return J[self.visible]

    def normal_matrix(self, x) -> np.ndarray:
        J = self.jacobian(x)
        JtJ = J.T @ J
        return JtJ.toarray() if sparse.issparse(JtJ) else JtJ

    def solve(self, x0, options: StacOptions, loss: str, f_scale: float):
        try:
            # MINPACK's LM (its own QR, no threaded LAPACK SVD) when the Jacobian is dense and the
            # loss plain; the trust-region reflective method for the sparse or robust cases
            lm = self.dense and loss == "linear"
            kw = (
                {}
                if lm
                else {
                    "loss": loss,
                    "f_scale": f_scale,
                    "tr_solver": "exact" if self.dense else "lsmr",
                }
            )
            return least_squares(
                self.residual,
                x0,
                jac=self.jacobian,
                method="lm" if lm else "trf",
                x_scale="jac",
                ftol=1e-8,
                xtol=1e-8,
                gtol=1e-8,
                max_nfev=max(4 * options.max_iterations, 20),
                **kw,
            )
        except (np.linalg.LinAlgError, ValueError) as exc:
            raise NumericalError(
                f"classical calibration failed ({exc}); check the nominal seed and the data"
            ) from None
