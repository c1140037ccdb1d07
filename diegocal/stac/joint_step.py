"""A joint Gauss-Newton step on (q_1:T, pot gains/biases) by the Schur complement.

Plain alternation (p-phase, q-phase) of thesis §2.2.3 converges slowly along directions where
a pot's gain/bias and the joint angles it reads co-move: when the pot is more precise than the
markers about its joint (a marker near the joint axis, a terminal link), each alternation
recovers only a small fraction of the remaining gain error. This step solves the Gauss-Newton
system of eq. 2.21 *jointly* in q_t and the pot parameters θ_p, eliminating the per-frame
blocks as in bundle adjustment:

.. math::

    \\begin{bmatrix} H_t & B_t \\\\ B_t^T & H_{θθ} \\end{bmatrix}
    \\begin{bmatrix} Δq_t \\\\ Δθ \\end{bmatrix} = -\\begin{bmatrix} g_t \\\\ g_θ \\end{bmatrix},
    \\quad (H_{θθ} - \\sum_t B_t^T H_t^{-1} B_t)\\, Δθ = -g_θ + \\sum_t B_t^T H_t^{-1} g_t

with, for pot j, ``B_t[:, j] = ∂s_j/∂q ⊗ c_tj``, ``c_tj = (gain_j / σ_j²) w_tj [s_tj, 1]`` (eq. 2.22),
so ``B_tᵀ H_t⁻¹ B_t`` needs only ``Ds_t H_t⁻¹ Ds_tᵀ`` (P x P). The caller keeps q + Δq (the
p-phase then re-solves all of θ in closed form) only when the total cost decreases.
"""

from __future__ import annotations

import numpy as np

from diegocal.stac.model import Observation, Params
from diegocal.stac.qphase import Noise, normal_equations


def free_mask(obs: Observation) -> np.ndarray:
    """(P, 2) which of (gain, bias) are estimated: encoders fix the gain, gauge pots the bias."""
    free = np.ones((obs.n_pots, 2), dtype=bool)
    free[obs.kinds == "encoder", 0] = False
    free[obs.fixed_bias, 1] = False
    return free


def joint_step(
    obs: Observation,
    params: Params,
    noise: Noise,
    q: np.ndarray,
    lam: np.ndarray,
    batch: int = 1000,
) -> tuple[np.ndarray, dict]:
    """The q part of one joint Gauss-Newton step (T, n), clipped to the joint limits, and the
    q-phase redundancy per sensor type at q (see :func:`diegocal.stac.qphase.redundancy`)."""
    P, (T, n) = obs.n_pots, q.shape
    S = np.zeros((P, 2, P, 2))
    rhs = np.zeros((P, 2))
    gth = np.zeros((P, 2))
    keep, used = [], {}
    for i in range(0, T, batch):
        sl = slice(i, min(i + batch, T))
        H, g, _, (s, _, _), red, (ds, wp, zp) = normal_equations(obs, params, noise, q, sl)
        used = {k: used.get(k, 0.0) + v for k, v in red.items()}
        diag = np.einsum("bii->bi", H)
        Hd = H + (lam[sl, None] * diag + 1e-9 * (1.0 + diag.max(1, keepdims=True)))[
            ..., None
        ] * np.eye(n)
        X = np.linalg.solve(
            Hd, np.concatenate([np.swapaxes(ds, 1, 2), g[..., None]], axis=2)
        )  # (B, n, P+1)
        M = ds @ X[:, :, :P]  # Ds H⁻¹ Dsᵀ (B, P, P)
        v = np.einsum("bpn,bn->bp", ds, X[:, :, P])  # Ds H⁻¹ g
        c = (
            (params.gain / noise.sig_p**2)[None, :, None]
            * wp[..., None]
            * np.stack([s, np.ones_like(s)], -1)
        )
        S -= np.einsum("tja,tlb,tjl->jalb", c, c, M)
        rhs += np.einsum("tja,tj->ja", c, v)
        Jth = np.stack([s, np.ones_like(s)], -1) / noise.sig_p[None, :, None]  # ∂r/∂(gain, bias)
        S[np.arange(P), :, np.arange(P), :] += np.einsum("tja,tjb->jab", Jth * wp[..., None], Jth)
        gth += np.einsum("tja,tj->ja", Jth * wp[..., None], zp)
        keep.append((sl, X, c))
    free = free_mask(obs).ravel()
    A = S.reshape(2 * P, 2 * P)[np.ix_(free, free)]
    b = (rhs - gth).ravel()[free]
    A = A + 1e-9 * np.trace(A) / max(len(b), 1) * np.eye(len(b))
    dth = np.zeros(2 * P)
    dth[free] = np.linalg.solve(A, b)
    dth = dth.reshape(P, 2)
    dq = np.empty_like(q)
    for sl, X, c in keep:
        coef = (c * dth[None]).sum(-1)  # (B, P): B_t Δθ = Dsᵀ coef
        dq[sl] = -X[:, :, P] - np.einsum("bnp,bp->bn", X[:, :, :P], coef)
    return np.clip(q + dq, obs.robot.lower, obs.robot.upper), used
