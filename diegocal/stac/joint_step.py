"""A joint Gauss-Newton step on (q_1:T, θ) by the Schur complement (bundle-adjustment style).

Plain alternation (p-phase, q-phase) of thesis §2.2.3 converges slowly along directions where
θ and q co-move: a pot's gain/bias against the joint angles it reads when the pot is more
precise than the markers about that joint, or the mocap rotation against a root joint's zero.
Each alternation then recovers only a small fraction of the remaining error. This step solves
the Gauss-Newton system of eq. 2.21 *jointly* in all q_t and θ = [gain, bias, d_1:M, ω, T0]
(ω a small rotation of R), eliminating the per-frame blocks:

.. math::

    (H_{θθ} - \\sum_t B_t^T H_t^{-1} B_t)\\, Δθ = -g_θ + \\sum_t B_t^T H_t^{-1} g_t,
    \\qquad B_t = J_{q,t}^T W_t J_{θ,t}

The reduced matrix is accumulated on an evenly spaced subset of frames (``max_frames``, scaled
to all frames; a quasi-Newton approximation), the right-hand side on every frame. The caller
applies Δθ, re-tracks q with a q-phase step and re-solves θ in closed form, and keeps the
result only when the total cost decreases.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.spatial.transform import Rotation

from diegocal.stac.model import Observation, Params
from diegocal.stac.qphase import Noise, normal_equations


def free_mask(obs: Observation) -> np.ndarray:
    """(Nθ,) which entries of θ = [gain (P), bias (P), d (3M), ω (3), T (3)] are estimated."""
    M = obs.n_markers
    gain = obs.kinds != "encoder"
    bias = ~obs.fixed_bias
    return np.concatenate([gain, bias, np.ones(3 * M + 6, dtype=bool)])


def _theta_jacobian(obs: Observation, params: Params, noise: Noise, s, Rl, pl, valid) -> np.ndarray:
    """∂r/∂θ (B, P + 3M, Nθ) of the standardised residuals (pots first, then marker coordinates)."""
    B, P, M = s.shape[0], obs.n_pots, obs.n_markers
    N = 2 * P + 3 * M + 6
    J = np.zeros((B, P + 3 * M, N))
    idx = np.arange(P)
    J[:, idx, idx] = s / noise.sig_p  # eq. 2.18-2.20: linear in gain ...
    J[:, idx, P + idx] = 1.0 / noise.sig_p  # ... and bias
    if M:
        xb = np.einsum("bmij,mj->bmi", Rl, params.xyz) + pl
        y = xb @ params.R.T  # R x_b
        RRl = np.einsum("ij,bmjk->bmik", params.R, Rl) / noise.sig_x  # ∂/∂d_m (eq. 2.11-2.12)
        skew = np.zeros((B, M, 3, 3))
        skew[..., 0, 1], skew[..., 0, 2], skew[..., 1, 2] = y[..., 2], -y[..., 1], y[..., 0]
        skew = (skew - np.swapaxes(skew, -1, -2)) / noise.sig_x  # −[R x_b]× (δR = exp(ω×) R)
        for m in range(M):
            rows = slice(P + 3 * m, P + 3 * m + 3)
            J[:, rows, 2 * P + 3 * m : 2 * P + 3 * m + 3] = RRl[:, m]
            J[:, rows, N - 6 : N - 3] = skew[:, m]
            J[:, rows, N - 3 :] = np.eye(3) / noise.sig_x
        J[:, P:] *= np.repeat(valid, 3, axis=1)[..., None]
    return J


def _theta_transpose_times(obs, params, noise, s, Rl, pl, v) -> np.ndarray:
    """J_θᵀ v summed over frames (Nθ,) without forming J_θ; v (B, P + 3M), invalid rows zero."""
    P, M = obs.n_pots, obs.n_markers
    vp = v[:, :P] / noise.sig_p
    out = [np.einsum("bp,bp->p", vp, s), vp.sum(0)]
    if M:
        vx = v[:, P:].reshape(-1, M, 3) / noise.sig_x
        y = (np.einsum("bmij,mj->bmi", Rl, params.xyz) + pl) @ params.R.T  # R x_b
        out.append(np.einsum("bmki,lk,bml->mi", Rl, params.R, vx).ravel())  # (R h_r)ᵀ v
        out.append(np.cross(y, vx).sum((0, 1)))  # (−[y]×)ᵀ v = y × v
        out.append(vx.sum((0, 1)))
    else:
        out += [np.zeros(0), np.zeros(3), np.zeros(3)]
    return np.concatenate(out)


def theta_step(
    obs: Observation,
    params: Params,
    noise: Noise,
    q: np.ndarray,
    lam: np.ndarray,
    batch: int = 500,
    max_frames: int = 250,
) -> tuple[Params, dict, dict]:
    """θ + Δθ from the reduced (Schur) system, the q-phase redundancy per sensor type and the
    standard errors of θ with q marginalised: ``{"gain", "bias" (P,), "xyz" (M, 3)}`` from the
    diagonal of the inverse reduced matrix (the residuals are standardised, so it is the
    covariance itself); NaN for the entries held fixed."""
    T, n = q.shape
    P, M = obs.n_pots, obs.n_markers
    N = 2 * P + 3 * M + 6
    stride = max(1, T // max_frames)
    S = np.zeros((N, N))
    rhs = np.zeros(N)
    used: dict = {}
    for i in range(0, T, batch):
        sl = slice(i, min(i + batch, T))
        H, g, _, (s, Rl, pl), red, ex = normal_equations(obs, params, noise, q, sl)
        used = {k: used.get(k, 0.0) + v for k, v in red.items()}
        B = H.shape[0]
        Jq = np.zeros((B, P + 3 * M, n))
        w = np.zeros((B, P + 3 * M))
        r = np.zeros((B, P + 3 * M))
        if noise.use_pots and P:
            Jq[:, :P] = ex["ds"] * (params.gain / noise.sig_p)[None, :, None]
            w[:, :P], r[:, :P] = ex["wp"], ex["zp"]
        if noise.use_markers and M:
            Jq[:, P:], w[:, P:], r[:, P:] = ex["Jx"], ex["wx"], ex["rx"].reshape(B, -1)
        diag = np.einsum("bii->bi", H)
        Hd = H + (lam[sl, None] * diag + 1e-9 * (1.0 + diag.max(1, keepdims=True)))[..., None] * np.eye(n)
        u = np.linalg.solve(Hd, g[..., None])[..., 0]  # H⁻¹ g
        v = w * (np.einsum("bkn,bn->bk", Jq, u) - r)
        rhs += _theta_transpose_times(obs, params, noise, s, Rl, pl, v)  # Bᵀ H⁻¹ g − g_θ
        pick = np.arange(sl.start, sl.stop) % stride == 0
        if pick.any():
            Jt = _theta_jacobian(obs, params, noise, s[pick], Rl[pick], pl[pick], ex["valid"][pick])
            WJt = Jt * w[pick][..., None]
            Bt = np.swapaxes(Jq[pick], 1, 2) @ WJt  # (b, n, Nθ)
            X = np.linalg.solve(Hd[pick], Bt)
            Wp, Jp = WJt.reshape(-1, N), Jt.reshape(-1, N)
            S += stride * (Wp.T @ Jp - Bt.reshape(-1, N).T @ X.reshape(-1, N))
    free = free_mask(obs)
    A = S[np.ix_(free, free)]
    A = A + 1e-9 * max(np.trace(A), 1.0) / max(free.sum(), 1) * np.eye(free.sum())
    d = np.zeros(N)
    d[free] = np.linalg.solve(A, rhs[free])
    var = np.full(N, np.nan)
    var[free] = np.diag(np.linalg.inv(A))
    sd = np.sqrt(np.maximum(var, 0.0))
    se = {"gain": sd[:P], "bias": sd[P : 2 * P], "xyz": sd[2 * P : 2 * P + 3 * M].reshape(M, 3)}
    new = replace(
        params,
        gain=params.gain + d[:P],
        bias=params.bias + d[P : 2 * P],
        xyz=params.xyz + d[2 * P : 2 * P + 3 * M].reshape(M, 3),
        R=Rotation.from_rotvec(d[N - 6 : N - 3]).as_matrix() @ params.R,
        T=params.T + d[N - 3 :],
    )
    return new, used, se
