"""Classical regression-based kinematic calibration, STAC's σp = 0 limit (thesis §2.2.1, §2.4.2).

With noise-free pots the pot term of the likelihood (eq. 2.21) becomes a constraint
(eq. 2.28). For one-pot-one-joint sensors (rotary, encoder) the constraint is solved
analytically, ``q_j = (p_j - bias_j) / gain_j`` (eq. 2.2), and the joint angles disappear
from the problem: the parameters θ = (gains, biases, R, T0, d_1:M) minimise the marker error
alone (eq. 2.29 = eq. 2.4),

.. math:: \\min_\\theta \\sum_{t,m} \\| \\hat x_{mt}(\\theta, q_t(p_t, \\theta)) - x_{mt} \\|^2 ,

solved by Levenberg-Marquardt on the normal equations (:mod:`.regression`): JᵀWJ and JᵀW r are
summed over batches of frames and, within a batch, per marker over the joints that move it
(chain rule through eq. 2.23's ∂x̂/∂q and the pot inverse of :mod:`.pot_inverse`), so neither
the dense Jacobian (T·M·3 x |θ|) nor ∂q/∂θ of all frames is ever held in memory.

Linear (gimbal, eq. 2.19-2.20) and tendon pots are the case the thesis says classical methods
cannot handle: by default :func:`calibrate_classical` refuses them by name.
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
from dataclasses import dataclass, replace

import numpy as np
import pinocchio as pin
from threadpoolctl import threadpool_limits

from diegocal.errors import FitError, NumericalError
from diegocal.io import Log
from diegocal.robot import PointSet, Robot, marker_points
from diegocal.stac.calibration import Calibration, FitInfo
from diegocal.stac.pot_inverse import batch_kinematics, joint_angles_from_pots, nonlinear_pots
from diegocal.stac.regression import MarkerRegression, base_points, levenberg_marquardt
from diegocal.stac.result import IterationRecord, StacOptions, StacResult
from diegocal.stac.scale import check_marker_scale

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
        return replace(template, gain_se=gse, bias_se=bse, marker_xyz_se=se[self.xyz].reshape(-1, 3))


# ---------------------------------------------------------------------------------- kinematics
def points_jacobian(robot: Robot, q: np.ndarray, points: PointSet):
    """Points (T, N, 3) m and ∂/∂q (T, N, 3, n) in the base frame (thesis eq. 2.23)."""
    bk = batch_kinematics(robot)
    if bk is None:
        return robot.points_jacobian(q, points)
    return bk.points_jacobian(bk.joint_poses(q), points)


def link_rotations(robot: Robot, q: np.ndarray, links) -> np.ndarray:
    """Rotation of each link in the base frame: (T, L, 3, 3)."""
    bk = batch_kinematics(robot)
    if bk is None:
        return robot.link_poses(q, links)[0]
    return bk.link_poses(bk.joint_poses(q), links)[0]


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


# ---------------------------------------------------------------------------------- the fit
def calibrate_classical(
    log: Log,
    robot: Robot,
    options: StacOptions | None = None,
    *,
    nonlinear: str = "refuse",
    q0=None,
    hold: tuple[str, ...] = (),
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
    hold : names of pots kept at their nominal gain and bias (not calibrated, standard errors
        NaN), e.g. the fixed point of an alternation with σp = 0 (see bench/bench_stac_compare.py)

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
    unknown = [name for name in hold if name not in robot.sensors.pot_names]
    if unknown:
        raise FitError(f"hold: {unknown[0]!r} is not a pot of {robot.name}")
    layout = ThetaLayout.for_robot(robot, frozen=(hard if nonlinear == "nominal" else ()) + tuple(hold))
    if q0 is not None:
        q0 = np.broadcast_to(np.asarray(q0, float), (pots.shape[0], robot.n_joints))
    # one BLAS thread: the products are many and small (per batch and marker), where threads only
    # add synchronisation (ten times the CPU time measured on a loaded two-core machine)
    with threadpool_limits(limits=1, user_api="blas"):
        inv = joint_angles_from_pots(robot, nominal, pots, q0=q0)
        xb = base_points(robot, inv.q, nominal.marker_links, nominal.marker_xyz)
        R0, T0 = kabsch(xb.reshape(-1, 3), markers.reshape(-1, 3))  # eq. 2.13-2.16 seed
        seed = replace(nominal, mocap_R=R0, mocap_T=T0)
        problem = MarkerRegression(robot, layout, seed, pots, markers, inv.q)
        max_nfev = max(4 * options.max_iterations, 20)
        res = levenberg_marquardt(problem, layout.pack(seed), max_nfev)
        if options.loss == "huber":
            # the Huber corner at huber_scale robust sigmas (MAD of the least-squares residuals)
            scale = options.huber_scale * max(1.4826 * np.median(np.abs(res.fun)), 1e-9)
            res = levenberg_marquardt(problem, res.x, max_nfev, huber=scale)
        if not np.isfinite(res.x).all():
            raise NumericalError("classical calibration diverged (non-finite parameters); check the nominal seed")
        fitted = layout.unpack(res.x, seed)
        q = problem.inverse(res.x)
        JtJ = problem.normal_equations(res.x)[0]
        dof = max(res.fun.size - np.linalg.matrix_rank(JtJ), 1)
        sigma = float(np.sqrt(np.sum(res.fun**2) / dof))
        se = packed_standard_errors(JtJ, sigma)
    seconds = time.perf_counter() - started
    fitted = layout.standard_errors(se, fitted)
    fitted = replace(
        fitted,
        sigma_pots=0.0,
        sigma_markers=sigma,
        fit=FitInfo(float(res.cost), int(res.nfev), res.converged, seconds),
    )
    record = IterationRecord(int(res.nfev), float(res.cost), 0.0, sigma, seconds)
    return StacResult(fitted, q, (record,))


def read_streams(log: Log, robot: Robot, who: str) -> tuple[np.ndarray, np.ndarray]:
    """The robot's pots (T, P) V and markers (T, M, 3) m from ``log``, in sensors.yaml order."""
    pots = log.stream("pots", needed_by=who).select(robot.sensors.pot_names).data
    markers = log.stream("markers", needed_by=who).select(robot.sensors.marker_names).data
    if pots.shape[0] < 2:
        raise FitError(f"{who} needs at least 2 samples, the log has {pots.shape[0]}")
    if not np.isfinite(markers).any():
        raise FitError(f"{who}: every marker sample is NaN (occluded)")
    check_marker_scale(markers, robot, robot.sensors.markers)  # a log in mm, as STAC's Observation checks
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
