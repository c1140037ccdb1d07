"""The classical calibration's least-squares problem, eq. 2.29, and its Levenberg-Marquardt solver.

The residuals are the visible marker coordinates (m) with the joint angles solved from the pots
(σp = 0, :func:`diegocal.stac.pot_inverse.joint_angles_from_pots`),

.. math:: r_{tm}(θ) = R\\,(h_r(q_t) d_m + h_p(q_t)) + T_0 - x_{tm}, \\qquad q_t = q(p_t, θ),

and θ = (free pot gains and biases, rotation vector of R, T0, d_1:M) in
:class:`~diegocal.stac.classical.ThetaLayout` order. A marker's rows depend only on the joints
that move its link (eq. 2.23), hence only on the pot parameters of those joints (eq. 2.2, or the
gimbal/tendon inverse), on (R, T0) and on its own d_m. :meth:`MarkerRegression.normal_equations`
builds that block, ``[∂x̂/∂q_A ∂q_A/∂θ_pots, ∂x̂/∂r, I_3, R h_r(q_t)]``, per batch of frames and
per marker and adds its weighted Gram matrix to JᵀWJ (|θ| x |θ|): memory is O(batch), not
O(T·M·3·|θ|), and the work O(T Σ_m |block_m|²) instead of O(T M |θ|²).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from diegocal.robot import PointSet, Robot
from diegocal.stac.calibration import Calibration
from diegocal.stac.pot_inverse import angle_derivatives, batch_kinematics, joint_angles_from_pots

#: frames per batch of the normal equations (memory, not results)
BATCH = 1000


def base_points(robot: Robot, q: np.ndarray, links, xyz: np.ndarray, batch: int = BATCH) -> np.ndarray:
    """Link-fixed points (N,) in the base frame for every frame: (T, N, 3), m (eq. 2.11)."""
    kin, points = batch_kinematics(robot), PointSet(tuple(links), np.asarray(xyz, float))
    out = np.empty((q.shape[0], len(points.links), 3))
    for i in range(0, q.shape[0], batch):
        sl = slice(i, i + batch)
        out[sl] = robot.points(q[sl], points) if kin is None else kin.points(kin.joint_poses(q[sl]), points)
    return out


def _kinematics(robot: Robot, q: np.ndarray, links, xyz: np.ndarray):
    """Points x (B, M, 3), their Jacobians ∂x/∂q (B, M, 3, n) and link rotations (B, M, 3, 3),
    all in the base frame (eq. 2.11, 2.23)."""
    kin, points = batch_kinematics(robot), PointSet(tuple(links), xyz)
    if kin is None:
        x, J = robot.points_jacobian(q, points)
        return x, J, robot.link_poses(q, links)[0]
    poses = kin.joint_poses(q)
    Rl, pl = kin.link_poses(poses, points.links)
    x = (Rl @ xyz[None, :, :, None])[..., 0] + pl
    J = np.empty((*x.shape, q.shape[1]))
    for c in range(3):  # row c of each point's Jacobian: its projection on the unit vector e_c
        e = np.zeros_like(x)
        e[..., c] = 1.0
        J[:, :, c] = kin.points_project(poses, x, points.links, e)
    return x, J, Rl


class MarkerRegression:
    """Residuals of eq. 2.29 and their Gauss-Newton sums, for :func:`levenberg_marquardt`.

    Parameters
    ----------
    robot : Robot
    layout : ThetaLayout of the free parameters
    template : Calibration holding the values of everything not in θ
    pots : (T, P) V; markers : (T, M, 3) m, NaN where occluded
    q_start : (T, n) rad, the first guess of the numerically solved joints (warm-started after)
    """

    def __init__(self, robot, layout, template: Calibration, pots, markers, q_start, batch: int = BATCH):
        self.robot, self.layout, self.template = robot, layout, template
        self.pots = pots
        self.visible = np.isfinite(markers).all(axis=-1)  # (T, M)
        self.markers = np.where(self.visible[..., None], markers, 0.0)
        self.q_warm = q_start
        self.batch = batch
        self._key = None

    def _evaluate(self, x: np.ndarray) -> None:
        key = x.tobytes()
        if key == self._key:
            return
        cal = self.layout.unpack(x, self.template)
        q = joint_angles_from_pots(self.robot, cal, self.pots, q0=self.q_warm).q
        self.q_warm = q
        xb = base_points(self.robot, q, cal.marker_links, cal.marker_xyz, self.batch)
        r = xb @ np.asarray(cal.mocap_R).T + cal.mocap_T - self.markers  # eq. 2.12
        r[~self.visible] = 0.0
        self._cal, self._q, self._r, self._key = cal, q, r, key

    def inverse(self, x: np.ndarray) -> np.ndarray:
        """The joint angles (T, n) rad the pots imply under θ = x."""
        self._evaluate(x)
        return self._q

    def residual(self, x: np.ndarray) -> np.ndarray:
        """Visible marker coordinates' residuals (N,), m, frame-major."""
        self._evaluate(x)
        return self._r[self.visible].reshape(-1)

    def normal_equations(self, x: np.ndarray, w: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """JᵀWJ (|θ|, |θ|) and JᵀW r (|θ|,) at θ = x; ``w`` (N,) weights of :meth:`residual`'s
        entries (default 1)."""
        self._evaluate(x)
        lay, cal = self.layout, self._cal
        W = np.zeros(self._r.shape)
        W[self.visible] = 1.0 if w is None else np.asarray(w, float).reshape(-1, 3)
        N, M = lay.size, lay.n_markers
        frame_cols = np.r_[lay.rot, lay.trans]
        A, g = np.zeros((N, N)), np.zeros(N)
        R = np.asarray(cal.mocap_R, float)
        Jexp = pin.Jexp3(pin.log3(R))
        for i in range(0, self._q.shape[0], self.batch):
            sl = slice(i, i + self.batch)
            q, r, wb = self._q[sl], self._r[sl], W[sl]
            B = q.shape[0]
            dq = angle_derivatives(self.robot, cal, q, lay)  # (B, n, K)
            xb, Jx, Rl = _kinematics(self.robot, q, cal.marker_links, cal.marker_xyz)
            Jx = np.einsum("ij,bmjn->bmin", R, Jx)  # eq. 2.23 in the mocap frame
            skew = np.zeros((B, M, 3, 3))  # ∂(R x)/∂r = −R [x]× J_exp(r) for R = exp([r]×)
            skew[..., 0, 1], skew[..., 0, 2], skew[..., 1, 2] = -xb[..., 2], xb[..., 1], -xb[..., 0]
            skew -= np.swapaxes(skew, -1, -2)
            drot = -(R @ skew) @ Jexp
            dxyz = np.einsum("ij,bmjk->bmik", R, Rl)
            eye = np.broadcast_to(np.eye(3), (B, 3, 3))
            for m in range(M):
                wm = wb[:, m].reshape(-1)
                if not wm.any():
                    continue
                joints = np.flatnonzero(np.any(Jx[:, m] != 0.0, axis=(0, 1)))  # those moving m
                dqm = dq[:, joints]
                cols = np.flatnonzero(np.any(dqm != 0.0, axis=(0, 1)))  # their pot parameters
                head = Jx[:, m][:, :, joints] @ dqm[:, :, cols]  # ∂x̂/∂q ∂q/∂θ_pots
                blk = np.concatenate([head, drot[:, m], eye, dxyz[:, m]], axis=2).reshape(3 * B, -1)
                idx = np.concatenate([cols, frame_cols, lay.xyz.start + 3 * m + np.arange(3)])
                A[np.ix_(idx, idx)] += blk.T @ (blk * wm[:, None])
                g[idx] += blk.T @ (wm * r[:, m].reshape(-1))
        return A, g


@dataclass(frozen=True)
class LeastSquares:
    """Where :func:`levenberg_marquardt` stopped: x, the residuals ``fun`` (N,), the cost
    (½ Σ r², or ½ Σ of Huber's ρ), residual evaluations and whether a tolerance was met."""

    x: np.ndarray
    fun: np.ndarray
    cost: float
    nfev: int
    converged: bool


def _cost(r: np.ndarray, huber: float | None) -> float:
    """½ Σ ρ(r): ρ = r² or Huber's, r² inside ±c and 2c|r| − c² outside (scipy's 'huber')."""
    if huber is None:
        return 0.5 * float(r @ r)
    a = np.abs(r)
    return 0.5 * float(np.where(a <= huber, r * r, 2 * huber * a - huber * huber).sum())


def levenberg_marquardt(
    problem, x0: np.ndarray, max_nfev: int, huber: float | None = None, tol: float = 1e-8
) -> LeastSquares:
    """Minimise ½ Σ ρ(r(x)) by Levenberg-Marquardt on the normal equations (IRLS weights for Huber).

    ``problem`` has ``residual(x) -> (N,)`` and ``normal_equations(x, w) -> (JᵀWJ, JᵀW r)``.
    The system is scaled by the column norms of J (MINPACK's ``diag``); each step solves
    ``(Â + λ I) δ̂ = −ĝ`` and is kept when the cost falls (λ / 3), else λ × 4. Stops when an
    accepted step lowers the cost by less than ``tol`` relative or moves x by less than ``tol``
    relative (scaled), when the gradient is orthogonal to the residual within ``tol`` (MINPACK's
    gtol), or after ``max_nfev`` residual evaluations (not converged).
    """
    x = np.array(x0, dtype=float)
    r = problem.residual(x)
    cost, nfev, lam, converged = _cost(r, huber), 1, 1e-3, False
    while nfev < max_nfev and not converged:
        w = None if huber is None else np.minimum(1.0, huber / np.maximum(np.abs(r), 1e-300))
        A, g = problem.normal_equations(x, w)
        d = np.sqrt(np.clip(np.diag(A), 0.0, None))
        d[d <= 0] = 1.0
        As, gs = A / np.outer(d, d), g / d
        if cost <= 0 or np.max(np.abs(gs)) <= tol * np.sqrt(2 * cost):
            converged = True
            break
        eye = np.eye(len(x))
        while nfev < max_nfev:
            try:
                step = -np.linalg.solve(As + lam * eye, gs) / d
            except np.linalg.LinAlgError:
                step = -np.linalg.lstsq(As + lam * eye, gs, rcond=None)[0] / d
            x_new = x + step
            r_new = problem.residual(x_new)
            nfev += 1
            c_new = _cost(r_new, huber)
            if np.isfinite(c_new) and c_new < cost:
                converged = (cost - c_new) <= tol * cost or np.linalg.norm(d * step) <= tol * (
                    tol + np.linalg.norm(d * x)
                )
                x, r, cost, lam = x_new, r_new, c_new, max(lam / 3.0, 1e-10)
                break
            lam *= 4.0
            if lam > 1e12:  # no descent direction left at this precision: a minimum
                converged = True
                break
    return LeastSquares(x, r, cost, nfev, converged)
