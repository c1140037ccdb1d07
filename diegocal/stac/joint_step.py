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

The reduced matrix is accumulated on an evenly spaced subset of frames (``max_frames``, 100,
scaled to all frames; a quasi-Newton approximation: each term is positive semi-definite, so the
estimate is too; 50, 100 and 250 frames took the same iterations to the same answer on diego at
5,000 frames), the right-hand side on every frame, from the q-phase's structured normal
equations (J_q u and J_θᵀ v without forming either Jacobian). The caller
applies Δθ, re-tracks q with a q-phase step and re-solves θ in closed form, and keeps the
result only when the total cost decreases.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.spatial.transform import Rotation

from diegocal.robot.batch import cross
from diegocal.stac.model import Observation, Params, State
from diegocal.stac.qphase import BlockDiag, Noise, base_points, block_solve, damped, map_batches, normal_equations


def free_mask(obs: Observation) -> np.ndarray:
    """(Nθ,) which entries of θ = [gain (P), bias (P), d (3M), ω (3), T (3)] are estimated."""
    M = obs.n_markers
    gain = (obs.kinds != "encoder") & ~obs.fixed_gain
    bias = ~obs.fixed_bias & ~obs.fixed_gain
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


def _theta_transpose_times(obs, params, noise, s, Rl, pl, v, xb=None) -> np.ndarray:
    """J_θᵀ v summed over frames (Nθ,) without forming J_θ; v (B, P + 3M), invalid rows zero."""
    return _theta_rows(obs, params, noise, s, Rl, pl, v, xb).sum(axis=0)


def _theta_rows(obs, params, noise, s, Rl, pl, v, xb=None) -> np.ndarray:
    """J_θ,tᵀ v_t of every frame (B, Nθ) without forming J_θ; v (B, P + 3M), invalid rows zero.
    ``xb``: the markers in the base frame (B, M, 3) at these poses and θ, when the caller has them
    (the normal equations' ``x``)."""
    P, M = obs.n_pots, obs.n_markers
    B = v.shape[0]
    vp = v[:, :P] / noise.sig_p
    out = [vp * s, vp]
    if M:
        vx = v[:, P:].reshape(-1, M, 3) / noise.sig_x
        y = _rotate(base_points(Rl, pl, params.xyz) if xb is None else xb, params.R.T)  # R x_b
        out.append(np.einsum("bmki,bmk->bmi", Rl, _rotate(vx, params.R)).reshape(B, 3 * M))  # (R h_r)ᵀ v
        out.append(cross(y, vx).sum(1))  # (−[y]×)ᵀ v = y × v
        out.append(vx.sum(1))
    else:
        out += [np.zeros((B, 0)), np.zeros((B, 3)), np.zeros((B, 3))]
    return np.concatenate(out, axis=1)


def _times_q(obs: Observation, params: Params, noise: Noise, ex: dict, u: np.ndarray) -> np.ndarray:
    """w (J_q u − r) (B, P + 3M) in residual space (pots, then marker coordinates), from the
    linearisation ``ex`` of :func:`~diegocal.stac.qphase.normal_equations`; u (B, n)."""
    B, P, M = u.shape[0], obs.n_pots, obs.n_markers
    out = np.zeros((B, P + 3 * M))
    if noise.use_pots and P:
        du = u @ obs.A.T
        if len(obs.linear):
            du[:, obs.linear] = np.einsum("blc,bc->bl", ex["lin"].ds_lin, u[:, obs.sparsity.lin_cols])
        out[:, :P] = ex["wp"] * (du * (params.gain / noise.sig_p) - ex["zp"])
    if noise.use_markers and M:
        vel = obs.kin.points_velocity(None, ex["x"], obs.marker_links, u, xi=ex["lin"].xi)  # eq. 2.23
        out[:, P:] = (ex["wx"][..., None] * (_rotate(vel, params.R.T) / noise.sig_x - ex["rx"])).reshape(B, -1)
    return out


def _rotate(v: np.ndarray, R: np.ndarray) -> np.ndarray:
    """v @ R for v (..., 3) as one (·, 3) x (3, 3) product (a broadcast matmul is one per frame)."""
    return (v.reshape(-1, 3) @ R).reshape(v.shape)


def _dense_q_jacobian(obs: Observation, params: Params, noise: Noise, q: np.ndarray, wp, wx) -> np.ndarray:
    """J_q (b, P + 3M, n) and the weights w (b, P + 3M) of a few frames q (b, n), for their
    robust weights wp (b, P) and wx (b, M)."""
    b, P, M = q.shape[0], obs.n_pots, obs.n_markers
    _, ds, _, _, Jx = obs.evaluate(q, params.xyz)
    Jq = np.zeros((b, P + 3 * M, q.shape[1]))
    w = np.zeros((b, P + 3 * M))
    if noise.use_pots and P:
        Jq[:, :P] = ds * (params.gain / noise.sig_p)[None, :, None]  # eq. 2.22
        w[:, :P] = wp
    if noise.use_markers and M:
        Jq[:, P:] = (np.einsum("ij,bmjn->bmin", params.R, Jx) / noise.sig_x).reshape(b, -1, q.shape[1])  # eq. 2.23
        w[:, P:] = np.repeat(wx, 3, axis=1)
    return Jq, w


def _q_jacobian(obs: Observation, params: Params, noise: Noise, xi, ds_lin, x, wp, wx) -> np.ndarray:
    """:func:`_dense_q_jacobian` from a kept linearisation instead of the forward kinematics: the
    joint twists xi (b, 6, n), ∂s/∂q of the linear pots ds_lin (b, L, c) and the markers in the
    base frame x (b, M, 3) (None without markers); a marker's column k is s_mk (ω_k × x_m + v_k)
    (eq. 2.23, s_mk = ±1 where joint k moves the marker, else 0)."""
    b, P, M = xi.shape[0], obs.n_pots, obs.n_markers
    n = xi.shape[2]
    Jq = np.zeros((b, P + 3 * M, n))
    w = np.zeros((b, P + 3 * M))
    if noise.use_pots and P:
        kp = params.gain / noise.sig_p
        Jq[:, :P] = obs.A * kp[:, None]  # eq. 2.22
        Jq[:, obs.linear[:, None], obs.sparsity.lin_cols] = ds_lin * kp[obs.linear, None]
        w[:, :P] = wp
    if noise.use_markers and M:
        sign = obs.kin._points_structure(obs.marker_links).sign  # (M, n)
        om, v = xi[:, None, :3], xi[:, None, 3:]  # (b, 1, 3, n)
        xm = x[..., None]  # (b, M, 3, 1)
        Jx = v + np.stack(
            [
                om[:, :, 1] * xm[:, :, 2] - om[:, :, 2] * xm[:, :, 1],
                om[:, :, 2] * xm[:, :, 0] - om[:, :, 0] * xm[:, :, 2],
                om[:, :, 0] * xm[:, :, 1] - om[:, :, 1] * xm[:, :, 0],
            ],
            axis=2,
        )  # (b, M, 3, n): ω × x + v
        Jx *= sign[None, :, None, :]
        Jq[:, P:] = (np.einsum("ij,bmjn->bmin", params.R, Jx) / noise.sig_x).reshape(b, -1, n)  # eq. 2.23
        w[:, P:] = np.repeat(wx, 3, axis=1)
    return Jq, w


def pick(Hd: BlockDiag, ex: dict, s, Rl, pl, k: np.ndarray) -> tuple:
    """What :func:`reduced_matrix` needs of the frames ``k`` of a batch: from its damped normal
    matrix Hd, the linearisation ``ex`` of :func:`~diegocal.stac.qphase.normal_equations` and
    s, Rl, pl."""
    wx = None if ex["wx"] is None else ex["wx"][k]
    x = None if ex["x"] is None else ex["x"][k]
    xi = np.moveaxis(ex["lin"].xi[:, k], 0, 1)
    return (Hd.take(k), ex["wp"][k], wx, s[k], Rl[k], pl[k], ex["valid"][k], xi, ex["lin"].ds_lin[k], x)


def reduced_matrix(obs: Observation, params: Params, noise: Noise, picked: list, chunk: int = 100) -> np.ndarray:
    """Σ_t J_θ,tᵀ W_t J_θ,t − B_tᵀ H_t⁻¹ B_t (Nθ, Nθ), the Schur complement's matrix (module
    docstring), over the frames ``picked``: a list of :func:`pick` per batch, taken ``chunk``
    frames at a time (the dense per-frame Jacobians stay small)."""
    wp, wx, s, Rl, pl, valid, xi, ds_lin, x = (
        None if picked[0][i] is None else np.concatenate([p[i] for p in picked]) for i in range(1, 10)
    )
    Hd = BlockDiag.concat([p[0] for p in picked])
    N = 2 * obs.n_pots + 3 * obs.n_markers + 6
    S = np.zeros((N, N))
    for i in range(0, s.shape[0], chunk):
        c = slice(i, i + chunk)
        Jq, w = _q_jacobian(
            obs, params, noise, xi[c], ds_lin[c], None if x is None else x[c], wp[c], None if wx is None else wx[c]
        )
        Jt = _theta_jacobian(obs, params, noise, s[c], Rl[c], pl[c], valid[c])
        WJt = Jt * w[..., None]
        S += _theta_gram(obs, Jt, WJt)
        Bt = np.swapaxes(Jq, 1, 2) @ WJt  # (b, n, Nθ)
        for ix, Hb in zip(Hd.index, Hd.blocks, strict=True):  # Bᵀ H⁻¹ B block by block, on the θ it sees
            Bb = Bt[:, ix]
            cols = np.flatnonzero(np.any(Bb != 0.0, axis=(0, 1)))
            Bb = Bb[:, :, cols]
            X = np.linalg.solve(Hb[c], Bb)
            S[np.ix_(cols, cols)] -= Bb.reshape(-1, len(cols)).T @ X.reshape(-1, len(cols))
    return S


def _theta_gram(obs: Observation, Jt: np.ndarray, WJt: np.ndarray) -> np.ndarray:
    """Σ_t J_θ,tᵀ W_t J_θ,t (Nθ, Nθ) from J_θ (b, P + 3M, Nθ) and W J_θ by its structure
    (:func:`_theta_jacobian`): a pot's row holds its gain and bias, a marker's three rows its
    position d_m, ω and T0; the products of the entries that are zero are left out."""
    P, M = obs.n_pots, obs.n_markers
    N = Jt.shape[2]
    S = np.zeros((N, N))
    p = np.arange(P)
    for a in (p, P + p):  # the pots' 2 x 2 blocks (gain, bias)
        for b in (p, P + p):
            S[a, b] = np.einsum("tp,tp->p", WJt[:, p, a], Jt[:, p, b])
    if M:
        m = np.arange(M)
        # each marker's nine columns: its d_m, then ω and T0 (shared by all markers)
        cols = np.concatenate([2 * P + 3 * m[:, None] + np.arange(3), np.broadcast_to(np.arange(N - 6, N), (M, 6))], 1)
        rows = P + 3 * m[:, None] + np.arange(3)  # (M, 3)
        K = Jt[:, rows[:, :, None], cols[:, None, :]]  # (b, M, 3, 9)
        WK = WJt[:, rows[:, :, None], cols[:, None, :]]
        G = np.einsum("tmik,tmil->mkl", WK, K)  # (M, 9, 9)
        for j in range(M):
            S[np.ix_(cols[j], cols[j])] += G[j]
    return S


def _schur_batch(obs: Observation, params: Params, noise: Noise, q, lam, sl: slice, stride: int, want_red: bool, st):
    """One batch's share of the reduced system: Bᵀ H⁻¹ g − g_θ (Nθ,), the redundancy, and what
    the reduced matrix needs of its frames t ≡ 0 (mod stride)."""
    H, g, _, (s, Rl, pl), red, ex = normal_equations(obs, params, noise, q, sl, want_red, st)
    Hd = damped(H, lam[sl], inplace=True)
    u = block_solve(Hd, g)  # H⁻¹ g
    v = _times_q(obs, params, noise, ex, u)
    rhs = _theta_transpose_times(obs, params, noise, s, Rl, pl, v, ex["x"])
    k = np.flatnonzero(np.arange(sl.start, sl.stop) % stride == 0)
    return rhs, red, pick(Hd, ex, s, Rl, pl, k)


def theta_step(
    obs: Observation,
    params: Params,
    noise: Noise,
    q: np.ndarray,
    lam: np.ndarray,
    batch: int = 250,
    max_frames: int = 100,
    want_red: bool = False,
    jobs: int = 1,
    damping: float = 0.0,
    st: State | None = None,
) -> tuple[Params, dict, dict]:
    """θ + Δθ from the reduced (Schur) system, the q-phase redundancy per sensor type (when
    ``want_red``; else empty) and the standard errors of θ with q marginalised:
    ``{"gain", "bias" (P,), "xyz" (M, 3)}`` from the diagonal of the inverse reduced matrix (the
    residuals are standardised, so it is the covariance itself); NaN for the entries held fixed.
    ``damping`` μ solves (A + μ diag A) Δθ = b instead (Marquardt: a shorter step, turned towards
    the gradient, after a full one overshot); the standard errors are the undamped ones.
    Batches of frames run in ``jobs`` threads; ``st``, the State at ``q``, lends its kept
    linearisation (:func:`~diegocal.stac.qphase.q_step`)."""
    T, n = q.shape
    P, M = obs.n_pots, obs.n_markers
    N = 2 * P + 3 * M + 6
    stride = max(1, T // max_frames)
    parts = map_batches(lambda sl: _schur_batch(obs, params, noise, q, lam, sl, stride, want_red, st), T, batch, jobs)
    rhs = sum(p[0] for p in parts)
    used = {k: sum(p[1][k] for p in parts) for k in parts[0][1]}
    # the reduced matrix from every stride-th frame, scaled (a quasi-Newton approximation)
    S = stride * reduced_matrix(obs, params, noise, [p[2] for p in parts])
    free = free_mask(obs)
    A = S[np.ix_(free, free)]
    A = A + 1e-9 * max(np.trace(A), 1.0) / max(free.sum(), 1) * np.eye(free.sum())
    d = np.zeros(N)
    d[free] = np.linalg.solve(A + damping * np.diag(np.diag(A)), rhs[free])
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
