"""Extended Kalman filter over [θ, q] for simultaneous tracking and calibration (thesis §2.4.1).

The state stacks the sensor parameters θ (pot gains and biases, mocap rotation vector r with
R = exp([r]×), T0, marker positions d_1:M; the :class:`~diegocal.stac.classical.ThetaLayout`
order) and the joint angles q. Its dynamics (eq. 2.24) are a random walk with covariance Σq on
q and zero process noise on θ; the observation (eq. 2.25-2.26) is every pot and every visible
marker coordinate with Gaussian noise σ_v:

.. math::

    \\begin{bmatrix}\\theta_{t+1}\\\\ q_{t+1}\\end{bmatrix} =
    \\begin{bmatrix}\\theta_t\\\\ q_t\\end{bmatrix} + w, \\quad
    w \\sim \\mathcal N(0, \\mathrm{diag}(0, \\Sigma_q)), \\qquad
    v_t = [\\hat p(\\theta_t, q_t); \\hat x(\\theta_t, q_t)] + z

The update linearises with the analytic Jacobian of eq. 2.27 (∂p̂/∂q eq. 2.22, ∂x̂/∂q eq. 2.23,
the θ blocks in closed form) and uses the Joseph form for the covariance. Occluded (NaN)
markers drop out of that frame's update. The filter may diverge — that is the point of the
thesis's Fig. 2.7 — so a non-finite state ends the pass and the result says so
(``fit.converged = False``; the joint angles from that frame on are NaN) instead of raising.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np

from diegocal.errors import FitError
from diegocal.io import Log
from diegocal.robot import Robot, marker_points, pots_jacobian
from diegocal.stac.calibration import Calibration, FitInfo
from diegocal.stac.classical import ThetaLayout, kabsch, marker_model, read_streams
from diegocal.stac.pot_inverse import joint_angles_from_pots
from diegocal.stac.result import IterationRecord, StacOptions, StacResult

#: a typical lever arm (m) turning an angle error into a linear/tendon pot's length error
_LEVER = 0.02


@dataclass(frozen=True)
class EkfOptions:
    """Noise model of the filter (thesis eq. 2.24-2.26); the thesis set these to the injected noise.

    sigma_pots : pot observation noise σ_p, V
    sigma_markers : marker observation noise σ_x, m
    q_step : random-walk standard deviation of each joint per frame, rad (Σq = q_step² I)
    q0_sd : standard deviation of the initial joint angles, rad
    seed_gain_rel : prior sd of a gain, relative to its seed value
    seed_bias : prior sd of a bias as an angle, rad (× |gain|; × 2 cm lever for linear/tendon pots)
    seed_rot : prior sd of the mocap rotation vector, rad
    seed_trans : prior sd of T0, m
    seed_xyz : prior sd of each marker coordinate, m
    passes : passes over the log; θ and its covariance carry over, q restarts from the seed q0
    """

    sigma_pots: float = 0.01
    sigma_markers: float = 0.005
    q_step: float = 0.05
    q0_sd: float = 0.1
    seed_gain_rel: float = 0.2
    seed_bias: float = 0.3
    seed_rot: float = 0.05
    seed_trans: float = 0.05
    seed_xyz: float = 0.03
    passes: int = 1


def prior_sd(robot: Robot, layout: ThetaLayout, seed: Calibration, ekf: EkfOptions) -> np.ndarray:
    """Prior standard deviations of the packed θ (ThetaLayout order) from :class:`EkfOptions`."""
    kinds = [p.kind for p in robot.sensors.pots]
    lever = np.array([1.0 if k in ("rotary", "encoder") else _LEVER for k in kinds])
    return np.concatenate(
        [
            ekf.seed_gain_rel * np.abs(seed.gain[layout.gain_pots]),
            ekf.seed_bias * (np.abs(seed.gain) * lever)[layout.bias_pots],
            np.full(3, ekf.seed_rot),
            np.full(3, ekf.seed_trans),
            np.full(3 * layout.n_markers, ekf.seed_xyz),
        ]
    )


def nominal_seed(robot: Robot, pots: np.ndarray, markers: np.ndarray) -> Calibration:
    """The nominal calibration with its mocap frame placed by Procrustes (eq. 2.13-2.16).

    ``pots`` (T, P) V and ``markers`` (T, M, 3) m; joint angles from the nominal pot inverse.
    """
    nominal = Calibration.nominal(robot)
    q = joint_angles_from_pots(robot, nominal, pots).q
    xb = robot.points(q, marker_points(robot, nominal.marker_xyz))
    R, T0 = kabsch(xb.reshape(-1, 3), markers.reshape(-1, 3))
    return replace(nominal, mocap_R=R, mocap_T=T0)


def calibrate_ekf(
    log: Log,
    robot: Robot,
    options: StacOptions | None = None,
    *,
    ekf: EkfOptions | None = None,
    seed: Calibration | None = None,
    seed_sd: np.ndarray | None = None,
    q0=None,
) -> StacResult:
    """Track q and calibrate θ with an extended Kalman filter (thesis eq. 2.24-2.27).

    Parameters
    ----------
    log : Log with ``pots`` (T, P) V and ``markers`` (T, M, 3) m (NaN = occluded); never its truth
    robot : Robot
    options : StacOptions (unused but for the common signature; ``quiet`` is honoured)
    ekf : EkfOptions, the noise model
    seed : the initial θ; default the nominal calibration with a Procrustes mocap frame
    seed_sd : (len θ,) prior sd of the packed θ; default :func:`prior_sd`
    q0 : (n,) initial joint angles, rad; default the seed's pot inverse of the first frame
        (the thesis set q0 to ground truth "as it diverges immediately otherwise")

    Returns
    -------
    StacResult: the final θ with standard errors sqrt(diag P_θ), the filtered q (T, n) rad
    (NaN after a divergence), ``fit.converged`` False when the filter diverged and
    ``sigma_pots``/``sigma_markers`` the RMS innovations of the last pass.
    """
    ekf = ekf or EkfOptions()
    if ekf.sigma_pots <= 0 or ekf.sigma_markers <= 0 or ekf.q_step < 0 or ekf.passes < 1:
        raise FitError("EKF noise levels must be positive (sigma_pots, sigma_markers) and passes >= 1")
    pots, markers = read_streams(log, robot, "EKF calibration")
    started = time.perf_counter()
    if seed is None:
        seed = nominal_seed(robot, pots, markers)
    seed = replace(seed, method="ekf")
    layout = ThetaLayout.for_robot(robot)
    theta = layout.pack(seed)
    sd = prior_sd(robot, layout, seed, ekf) if seed_sd is None else np.asarray(seed_sd, float)
    if sd.shape != theta.shape:
        raise FitError(f"seed_sd: expected shape {theta.shape}, got {sd.shape}")
    if q0 is None:
        q0 = joint_angles_from_pots(robot, seed, pots[:1]).q[0]
    q0 = np.asarray(q0, float).reshape(robot.n_joints)
    filt = _Filter(robot, layout, seed, ekf)
    P = np.diag(np.concatenate([sd**2, np.full(robot.n_joints, ekf.q0_sd**2)]))
    z = np.concatenate([theta, q0])
    history = []
    for k in range(ekf.passes):
        z[layout.size :] = q0
        if k:
            P[layout.size :, :] = 0.0
            P[:, layout.size :] = 0.0
            P[layout.size :, layout.size :] = np.eye(robot.n_joints) * ekf.q0_sd**2
        z, P, q, stats = filt.run(z, P, pots, markers)
        history.append(
            IterationRecord(k + 1, stats.cost, stats.rms_pots, stats.rms_markers, time.perf_counter() - started)
        )
        if stats.diverged_at is not None:
            break
    diverged = stats.diverged_at is not None
    cal = layout.unpack(z[: layout.size], seed) if np.isfinite(z[: layout.size]).all() else seed
    se = np.sqrt(np.clip(np.diag(P)[: layout.size], 0.0, None)) if not diverged else np.full(layout.size, np.nan)
    cal = layout.standard_errors(se, cal)
    cal = replace(
        cal,
        sigma_pots=stats.rms_pots,
        sigma_markers=stats.rms_markers,
        fit=FitInfo(stats.cost, len(history), not diverged, time.perf_counter() - started),
    )
    return StacResult(cal, q, tuple(history))


@dataclass(frozen=True)
class _PassStats:
    cost: float
    rms_pots: float
    rms_markers: float
    diverged_at: int | None


class _Filter:
    """One EKF pass; the state is z = [θ (layout order), q]."""

    def __init__(self, robot: Robot, layout: ThetaLayout, template: Calibration, ekf: EkfOptions):
        self.robot, self.layout, self.template, self.ekf = robot, layout, template, ekf
        self.n = robot.n_joints
        P = len(robot.sensors.pots)
        ng, nb = len(layout.gain_pots), len(layout.bias_pots)
        self.gain_rows = layout.gain_pots  # ∂p̂_i/∂gain_i = s_i  (eq. 2.18-2.20)
        self.bias_cols = ng + np.arange(nb)  # ∂p̂_i/∂bias_i = 1
        self.n_pots = P

    def observe(self, z: np.ndarray, visible: np.ndarray):
        """Predicted [pots; visible marker coordinates] and the Jacobian of eq. 2.27."""
        lay, n = self.layout, self.n
        cal = lay.unpack(z[: lay.size], self.template)
        q = z[lay.size :][None, :]
        s, dp_dq = pots_jacobian(self.robot, q, cal.gain)
        mm = marker_model(self.robot, q, cal)
        P, M = self.n_pots, lay.n_markers
        H = np.zeros((P + 3 * M, lay.size + n))
        H[self.gain_rows, np.arange(len(self.gain_rows))] = s[0, self.gain_rows]
        H[lay.bias_pots, self.bias_cols] = 1.0
        H[:P, lay.size :] = dp_dq[0]
        H[P:, lay.rot] = mm.drot[0].reshape(3 * M, 3)
        H[P:, lay.trans] = np.tile(np.eye(3), (M, 1))
        for m in range(M):
            H[P + 3 * m : P + 3 * m + 3, lay.xyz.start + 3 * m : lay.xyz.start + 3 * m + 3] = mm.dxyz[0, m]
        H[P:, lay.size :] = mm.dq[0].reshape(3 * M, n)
        h = np.concatenate([s[0] * cal.gain + cal.bias, mm.x[0].reshape(-1)])
        keep = np.concatenate([np.ones(P, bool), visible])
        return h[keep], H[keep]

    def run(self, z, P, pots, markers):
        ekf, lay = self.ekf, self.layout
        T = pots.shape[0]
        q_out = np.full((T, self.n), np.nan)
        Q = np.zeros(len(z))
        Q[lay.size :] = ekf.q_step**2  # eq. 2.24: zero noise on θ
        cost, sq_p, sq_x, n_x = 0.0, 0.0, 0.0, 0
        diverged_at = None
        eye = np.eye(len(z))
        for t in range(T):
            if t:
                P = P + np.diag(Q)  # predict: random walk
            visible = np.isfinite(markers[t]).reshape(-1)
            y = np.concatenate([pots[t], markers[t].reshape(-1)[visible]])
            noise = np.concatenate(
                [
                    np.full(self.n_pots, ekf.sigma_pots**2),
                    np.full(visible.sum(), ekf.sigma_markers**2),
                ]
            )
            try:
                h, H = self.observe(z, visible)
                nu = y - h  # innovation
                S = H @ P @ H.T + np.diag(noise)
                K = np.linalg.solve(S, H @ P).T  # P Hᵀ S⁻¹ (S, P symmetric)
                z = z + K @ nu
                A = eye - K @ H
                P = A @ P @ A.T + (K * noise) @ K.T  # Joseph form
                P = 0.5 * (P + P.T)
                cost += 0.5 * float(nu @ np.linalg.solve(S, nu))
            except (np.linalg.LinAlgError, ValueError, FloatingPointError):
                diverged_at = t
                break
            if not (np.isfinite(z).all() and np.isfinite(P).all()) or np.abs(z[lay.size :]).max() > 1e3:
                diverged_at = t
                break
            q_out[t] = z[lay.size :]
            sq_p += float(nu[: self.n_pots] @ nu[: self.n_pots])
            sq_x += float(nu[self.n_pots :] @ nu[self.n_pots :])
            n_x += int(visible.sum())
        done = max(t + (diverged_at is None), 1)
        stats = _PassStats(
            cost if diverged_at is None else float("inf"),
            float(np.sqrt(sq_p / (done * self.n_pots))) if self.n_pots else float("nan"),
            float(np.sqrt(sq_x / n_x)) if n_x else float("nan"),
            diverged_at,
        )
        return z, P, q_out, stats
