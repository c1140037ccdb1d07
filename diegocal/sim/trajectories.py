"""Joint trajectories for the dynamics simulator: excitation, figure-eights, closed-loop roll-outs.

Prescribed trajectories (:func:`excitation`, :func:`figure_eight`) give q, qd, qdd directly and the
simulator computes the torque by inverse dynamics. Integrated ones (:func:`rollout`) drive the true
forward dynamics with a torque law, e.g. the LQR balance of the reaction wheel (thesis §3.4.2,
"pole-up": :func:`lqr_gain`) or sum-of-sines motor commands ("pole-down").

Every array is float64, samples first: time (T,) s, q (T, n) rad, qd (T, n) rad/s,
qdd (T, n) rad/s².
Random choices come from an explicit ``numpy.random.Generator``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pinocchio as pin
import scipy.linalg

from diegocal.errors import NumericalError, RobotConfigError
from diegocal.sim.effects import SimOptionError

#: Joints whose range exceeds this (rad) are treated as continuous: excitation stays within ±π.
WIDE_RANGE = 2.0 * np.pi


@dataclass(frozen=True)
class JointTrajectory:
    """A sampled joint trajectory: time (T,) s; q (T, n) rad; qd (T, n) rad/s; qdd (T, n) rad/s²;
    ``tau`` (T, n) N·m: the applied generalized forces for integrated roll-outs, else None."""

    time: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    tau: np.ndarray | None = None


def time_base(duration: float, rate_hz: float) -> np.ndarray:
    """Sample times (T,) s of a log of ``duration`` seconds at ``rate_hz``; at least two samples."""
    if not np.isfinite(duration) or duration <= 0:
        raise SimOptionError(f"duration must be a positive number of seconds, got {duration}")
    if not np.isfinite(rate_hz) or rate_hz <= 0:
        raise SimOptionError(f"rate must be a positive number of Hz, got {rate_hz}")
    n = int(round(duration * rate_hz))
    if n < 2:
        raise SimOptionError(f"duration {duration} s at {rate_hz} Hz gives fewer than 2 samples")
    return np.arange(n) / rate_hz


def sum_of_sines(
    time: np.ndarray,
    n_channels: int,
    rng: np.random.Generator,
    amplitude,
    f_min: float = 0.05,
    f_max: float = 0.5,
    n_sines: int = 5,
) -> tuple[np.ndarray, ...]:
    """Random multi-sine per channel and its two time derivatives, peak-bounded by ``amplitude``.

    x_j(t) = Σ_k a_jk sin(2π f_jk t + φ_jk), with f ~ U(f_min, f_max) Hz and the a_jk rescaled so
    that Σ_k |a_jk| = amplitude_j (a hard bound on |x_j|).

    Returns
    -------
    x, xd, xdd : ndarrays of shape (T, n_channels)
    """
    amplitude = np.broadcast_to(np.asarray(amplitude, dtype=float), (n_channels,))
    f = rng.uniform(f_min, f_max, size=(n_channels, n_sines))
    a = rng.uniform(0.2, 1.0, size=(n_channels, n_sines))
    a *= (amplitude / a.sum(axis=1))[:, None]
    phi = rng.uniform(0.0, 2.0 * np.pi, size=(n_channels, n_sines))
    w = 2.0 * np.pi * f  # (n, K) rad/s
    arg = w[None] * time[:, None, None] + phi[None]  # (T, n, K)
    x = (a * np.sin(arg)).sum(-1)
    xd = (a * w * np.cos(arg)).sum(-1)
    xdd = -(a * w**2 * np.sin(arg)).sum(-1)
    return x, xd, xdd


def excitation(
    lower: np.ndarray,
    upper: np.ndarray,
    time: np.ndarray,
    rng: np.random.Generator,
    margin: float = 0.1,
    f_max: float = 0.5,
    n_sines: int = 5,
) -> JointTrajectory:
    """Sum-of-sinusoids excitation about the middle of each joint's range, inside its limits.

    The peak excursion is (1 − margin) × half the range; joints with a range wider than 2π
    (continuous joints declared revolute) swing within ±(1 − margin)·π about 0.
    """
    lower, upper = np.asarray(lower, float), np.asarray(upper, float)
    wide = (upper - lower) > WIDE_RANGE
    centre = np.where(wide, 0.0, 0.5 * (lower + upper))
    half = np.where(wide, np.pi, 0.5 * (upper - lower))
    x, xd, xdd = sum_of_sines(
        time, lower.size, rng, (1.0 - margin) * half, f_max=f_max, n_sines=n_sines
    )
    # stretch so the peak excursion reaches the bound (random phases rarely add up to it)
    stretch = (1.0 - margin) * half / np.maximum(np.abs(x).max(axis=0), 1e-12)
    return JointTrajectory(time, centre + stretch * x, stretch * xd, stretch * xdd)


def whirl(
    lower: np.ndarray,
    upper: np.ndarray,
    time: np.ndarray,
    rng: np.random.Generator,
    speed: float = np.pi,
    variation: float = 0.6,
    f_max: float = 0.5,
) -> JointTrajectory:
    """Continuous rotation in one direction of every joint with a range of at least 2π (others get
    :func:`excitation`): q = wrap(φ₀ + ω t + Σ a_k sin(2π f_k t + φ_k)) into [lower, lower + 2π).

    ω = ``speed`` rad/s; the multi-sine's velocity stays within ±``variation``·ω, so qd > 0 at all
    times. A pendulum driven round and round passes a position-dependent friction in one direction
    only, so the friction acts like a position-dependent torque (thesis §3.1.1's irregularity).
    """
    lower, upper = np.asarray(lower, float), np.asarray(upper, float)
    out = excitation(lower, upper, time, rng)
    q, qd, qdd = out.q.copy(), out.qd.copy(), out.qdd.copy()
    for j in np.flatnonzero((upper - lower) >= WIDE_RANGE - 1e-6):
        x, xd, xdd = sum_of_sines(time, 1, rng, 1.0, f_max=f_max)
        gain = variation * speed / max(np.abs(xd).max(), 1e-12)
        raw = rng.uniform(0, 2 * np.pi) + speed * time + gain * x[:, 0]
        q[:, j] = lower[j] + np.mod(raw - lower[j], 2 * np.pi)
        qd[:, j], qdd[:, j] = speed + gain * xd[:, 0], gain * xdd[:, 0]
    return JointTrajectory(time, q, qd, qdd)


def figure_eight(
    model: pin.Model,
    frame: int,
    time: np.ndarray,
    centre: np.ndarray,
    q_start: np.ndarray,
    plane: str = "horizontal",
    size=(0.15, 0.08),
    period: float = 4.0,
    oversample: int = 4,
) -> JointTrajectory:
    """Joint trajectory whose frame (index ``frame``) traces a figure-eight, thesis Fig. 3.8.

    p(t) = centre + a sin(ωt) e1 + b sin(2ωt) e2, with (e1, e2) = (x, y) for ``horizontal`` and
    (x, z) for ``vertical``; ω = 2π/period. Positions (metres, world frame) are tracked by damped
    least-squares IK on Pinocchio's frame Jacobian, warm-started from ``q_start`` so the solution is
    continuous; qd and qdd are central differences on a grid ``oversample`` times finer.
    """
    if plane not in ("horizontal", "vertical"):
        raise SimOptionError(
            f"figure-eight plane must be 'horizontal' or 'vertical', got {plane!r}"
        )
    if not 0 <= frame < len(model.frames):
        raise RobotConfigError(f"robot has no frame {frame} for the figure-eight")
    fid, name = frame, model.frames[frame].name
    data = model.createData()
    dt = (time[1] - time[0]) / oversample
    fine = (
        time[0]
        + dt * np.arange((time.size - 1) * oversample + 1 + 2 * oversample)
        - dt * oversample
    )
    w = 2.0 * np.pi / period
    e2 = np.array([0.0, 1.0, 0.0]) if plane == "horizontal" else np.array([0.0, 0.0, 1.0])
    target = (
        centre[None]
        + size[0] * np.sin(w * fine)[:, None] * np.array([1.0, 0.0, 0.0])
        + size[1] * np.sin(2 * w * fine)[:, None] * e2
    )
    q = np.asarray(q_start, float).copy()
    out = np.empty((fine.size, model.nq))
    lwa = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
    for i, p in enumerate(target):
        for _ in range(50):
            pin.framesForwardKinematics(model, data, q)
            err = p - data.oMf[fid].translation
            if np.linalg.norm(err) < 1e-10:
                break
            J = pin.computeFrameJacobian(model, data, q, fid, lwa)[:3]
            q = q + J.T @ np.linalg.solve(J @ J.T + 1e-8 * np.eye(3), err)
        if np.linalg.norm(err) > 1e-6:
            raise NumericalError(
                f"figure-eight point {p.round(3).tolist()} is out of reach of {name!r}; "
                "reduce the size or move the centre"
            )
        out[i] = q
    if (out < model.lowerPositionLimit - 1e-9).any() or (
        out > model.upperPositionLimit + 1e-9
    ).any():
        raise NumericalError(
            "figure-eight leaves the joint limits; reduce the size or move the centre"
        )
    qd = np.gradient(out, dt, axis=0)
    qdd = np.gradient(qd, dt, axis=0)
    keep = slice(oversample, oversample + (time.size - 1) * oversample + 1, oversample)
    return JointTrajectory(time, out[keep], qd[keep], qdd[keep])


def ou_noise(
    n_samples: int,
    n_channels: int,
    dt: float,
    sigma: float,
    corr_time: float,
    rng: np.random.Generator,
) -> np.ndarray:
    """Ornstein-Uhlenbeck (band-limited) noise, stationary std ``sigma``, shape (T, n_channels)."""
    a = np.exp(-dt / corr_time)
    out = np.empty((n_samples, n_channels))
    x = sigma * rng.standard_normal(n_channels)
    step = sigma * np.sqrt(1.0 - a * a)
    for t in range(n_samples):
        out[t] = x
        x = a * x + step * rng.standard_normal(n_channels)
    return out


def lqr_gain(A: np.ndarray, B: np.ndarray, Q: np.ndarray, R: np.ndarray) -> np.ndarray:
    """Continuous-time LQR gain K (m, 2n) for u = −K x (scipy's continuous algebraic Riccati)."""
    try:
        P = scipy.linalg.solve_continuous_are(A, B, Q, R)
    except (np.linalg.LinAlgError, ValueError) as exc:
        raise NumericalError(
            f"LQR: the Riccati equation has no stabilising solution ({exc}); "
            "is the actuated joint able to balance the system?"
        ) from None
    return np.linalg.solve(R, B.T @ P)


def rollout(
    forward: Callable,
    time: np.ndarray,
    q0: np.ndarray,
    qd0: np.ndarray,
    torque: Callable,
    substeps: int = 4,
) -> JointTrajectory:
    """Integrate qdd = forward(q, qd, tau) with RK4, tau = torque(k, q, qd) held over each sample.

    Parameters
    ----------
    forward : callable (q (n,), qd (n,), tau (n,)) -> qdd (n,), the TRUE forward dynamics
    time : (T,) s, uniform
    torque : callable (k, q (n,), qd (n,)) -> tau (n,) N·m applied during sample k (zero-order hold)

    Returns
    -------
    JointTrajectory with q, qd at the sample times, qdd = forward(q, qd, tau) there, and tau.
    """
    dt = (time[1] - time[0]) / substeps
    n = q0.size
    q, qd = np.array(q0, float), np.array(qd0, float)
    Q, QD, QDD, TAU = (np.empty((time.size, n)) for _ in range(4))
    for k in range(time.size):
        u = np.asarray(torque(k, q, qd), float)
        Q[k], QD[k], TAU[k] = q, qd, u
        QDD[k] = forward(q, qd, u)
        if not np.isfinite(QDD[k]).all() or np.abs(qd).max() > 1e4:
            raise NumericalError(
                f"roll-out diverged at t = {time[k]:.3f} s; lower the torques or the step"
            )
        for _ in range(substeps):
            k1v, k1a = qd, forward(q, qd, u)
            k2v, k2a = qd + 0.5 * dt * k1a, forward(q + 0.5 * dt * k1v, qd + 0.5 * dt * k1a, u)
            k3v, k3a = qd + 0.5 * dt * k2a, forward(q + 0.5 * dt * k2v, qd + 0.5 * dt * k2a, u)
            k4v, k4a = qd + dt * k3a, forward(q + dt * k3v, qd + dt * k3a, u)
            q = q + dt / 6.0 * (k1v + 2 * k2v + 2 * k3v + k4v)
            qd = qd + dt / 6.0 * (k1a + 2 * k2a + 2 * k3a + k4a)
    return JointTrajectory(time, Q, QD, QDD, TAU)
