"""STAC q-phase: per-frame joint angles with θ fixed, damped Gauss-Newton (thesis §2.3.4, eq. 2.21).

Each frame t solves, independently (eq. 2.6),

.. math:: q_t^* = \\arg\\min_{q_t} \\sum_m \\rho(\\|\\hat x_{mt} - x_{mt}\\| / \\sigma_x)
          + \\sum_j \\rho((\\hat p_{jt} - p_{jt}) / \\sigma_{p,kind(j)})

with ρ(z) = z²/2 (Gaussian, eq. 2.21) or Huber's loss. One Levenberg-Marquardt step per call:
the batched normal equations ``(JᵀWJ + λ diag(JᵀWJ)) δ = −JᵀW r`` are solved with
``np.linalg.solve`` on (B, n, n), the step is projected onto the joint limits, and each frame
keeps its own damping λ_t (accept: λ/3, reject: λ·4). Jacobians are eq. 2.22 (pots) and eq. 2.23
(markers) from :mod:`diegocal.robot.batch`. Batches run in threads (``jobs``): numpy
releases the GIL in the heavy products, and no robot model is pickled.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from diegocal.stac.model import MARKERS, Observation, Params, State


@dataclass(frozen=True)
class Noise:
    """Per-reading noise levels: sig_p (P,) in V and sig_x in m, plus loss settings."""

    sig_p: np.ndarray
    sig_x: float
    loss: str = "linear"
    huber: float = 3.0
    use_pots: bool = True
    use_markers: bool = True


def rho(z: np.ndarray, loss: str, k: float) -> np.ndarray:
    """Loss of standardised residuals z (any shape): z²/2 or Huber."""
    if loss == "huber":
        a = np.abs(z)
        return np.where(a <= k, 0.5 * z * z, k * a - 0.5 * k * k)
    return 0.5 * z * z


def irls_weight(z: np.ndarray, loss: str, k: float) -> np.ndarray:
    """IRLS weight ρ'(z)/z: 1 (Gaussian) or min(1, k/|z|) (Huber)."""
    if loss == "huber":
        return np.minimum(1.0, k / np.maximum(np.abs(z), 1e-300))
    return np.ones_like(z)


def residuals(obs: Observation, params: Params, noise: Noise, s, Rl, pl, pots, markers, valid):
    """Standardised residuals of a batch: pots (B, P), marker norms (B, M) and vectors (B, M, 3)."""
    zp = (params.gain * s + params.bias - pots) / noise.sig_p
    xb = np.einsum("bmij,mj->bmi", Rl, params.xyz) + pl
    rx = np.where(valid[..., None], (xb @ params.R.T + params.T - np.nan_to_num(markers)) / noise.sig_x, 0.0)
    return zp, np.linalg.norm(rx, axis=-1), rx


def frame_cost(obs, params, noise, s, Rl, pl, pots, markers, valid) -> np.ndarray:
    """Per-frame objective of eq. 2.21 (B,)."""
    zp, zx, _ = residuals(obs, params, noise, s, Rl, pl, pots, markers, valid)
    c = np.zeros(s.shape[0])
    if noise.use_pots:
        c += rho(zp, noise.loss, noise.huber).sum(1)
    if noise.use_markers:
        c += rho(zx, noise.loss, noise.huber).sum(1)
    return c


def normal_equations(obs: Observation, params: Params, noise: Noise, q: np.ndarray, sl: slice, want_red: bool = True):
    """JᵀWJ (B, n, n), gradient JᵀW r (B, n), per-frame cost (B,), the evaluation at q[sl] and the
    redundancy of each sensor type (dict, summed over the batch; see :func:`redundancy`)."""
    q = q[sl]
    pots, markers, valid = obs.pots[sl], obs.markers[sl], obs.valid[sl]
    s, ds, Rl, pl, Jx = obs.evaluate(q, params.xyz)
    zp, zx, rx = residuals(obs, params, noise, s, Rl, pl, pots, markers, valid)
    B, n = q.shape
    H = np.zeros((B, n, n))
    g = np.zeros((B, n))
    c0 = np.zeros(B)
    parts = {}
    wp = np.zeros_like(zp)
    J = w3 = None
    if noise.use_pots and obs.n_pots:
        Jp = ds * (params.gain / noise.sig_p)[None, :, None]  # eq. 2.22
        wp = irls_weight(zp, noise.loss, noise.huber)
        for kind in dict.fromkeys(obs.kinds):
            k = obs.kinds == kind
            parts[kind] = np.swapaxes(Jp[:, k], 1, 2) @ (Jp[:, k] * wp[:, k, None])
            H += parts[kind]
        g += np.einsum("bpn,bp->bn", Jp, wp * zp)
        c0 += rho(zp, noise.loss, noise.huber).sum(1)
    if noise.use_markers and obs.n_markers:
        wx = irls_weight(zx, noise.loss, noise.huber) * valid
        J = (np.einsum("ij,bmjn->bmin", params.R, Jx) / noise.sig_x).reshape(B, -1, n)  # eq. 2.23
        w3 = np.repeat(wx, 3, axis=1)
        parts[MARKERS] = np.swapaxes(J, 1, 2) @ (J * w3[..., None])
        H += parts[MARKERS]
        g += np.einsum("brn,br->bn", J, w3 * rx.reshape(B, -1))
        c0 += rho(zx, noise.loss, noise.huber).sum(1)
    extra = {"ds": ds, "wp": wp, "zp": zp, "Jx": J, "wx": w3, "rx": rx, "valid": valid}
    return H, g, c0, (s, Rl, pl), redundancy(H, parts) if want_red else {}, extra


def redundancy(H: np.ndarray, parts: dict) -> dict:
    """Variance-component redundancy per sensor type: tr(H⁻¹ H_g) summed over frames.

    Fitting q_t absorbs n degrees of freedom per frame; the share of type g is the trace of
    its block of the hat matrix, tr((JᵀWJ)⁻¹ J_gᵀ W J_g). §2.3.5's re-estimate σ_g² = RSS_g / N_g
    ignores this and collapses to 0 when a type can be fitted exactly (one rotary pot per joint);
    σ_g² = RSS_g / (N_g − tr_g) (Helmert/Förstner variance-component estimation) does not.
    Returns {group: Σ_t tr_g}.
    """
    n = H.shape[-1]
    Hi = np.linalg.inv(H + 1e-9 * (1.0 + np.einsum("bii->b", H))[:, None, None] * np.eye(n))
    return {g: float(np.einsum("bij,bji->", Hi, Hg)) for g, Hg in parts.items()}


def _step_batch(obs: Observation, params: Params, noise: Noise, q, lam, sl, want_red=True):
    lo, hi = obs.lower, obs.upper
    H, g, c0, (s, Rl, pl), red, _ = normal_equations(obs, params, noise, q, sl, want_red)
    q, lam = q[sl], lam[sl]
    pots, markers, valid = obs.pots[sl], obs.markers[sl], obs.valid[sl]
    n = q.shape[1]
    diag = np.einsum("bii->bi", H)
    A = H + (lam[:, None] * diag + 1e-9 * (1.0 + diag.max(1, keepdims=True)))[..., None] * np.eye(n)
    delta = np.linalg.solve(A, -g[..., None])[..., 0]
    cand = np.clip(q + delta, lo, hi)  # projection onto the joint limits
    s1, _, Rl1, pl1, _ = obs.evaluate(cand)
    c1 = frame_cost(obs, params, noise, s1, Rl1, pl1, pots, markers, valid)
    ok = c1 <= c0
    q_new = np.where(ok[:, None], cand, q)
    lam_new = np.where(ok, np.maximum(lam / 3.0, 1e-7), np.minimum(lam * 4.0, 1e7))
    st = (
        np.where(ok[:, None], s1, s),
        np.where(ok[:, None, None, None], Rl1, Rl),
        np.where(ok[:, None, None], pl1, pl),
    )
    return q_new, lam_new, st, np.where(ok, c1, c0), red


def q_step(
    obs: Observation,
    params: Params,
    noise: Noise,
    q: np.ndarray,
    lam: np.ndarray,
    batch: int = 1000,
    jobs: int = 1,
    want_red: bool = True,
):
    """One LM step on every frame.

    Returns (q (T, n), λ (T,), State at the new q, cost (T,), redundancy {group: Σ tr_g} at
    the old q; empty unless ``want_red``: it costs one n x n inverse per frame).
    """
    slices = [slice(i, min(i + batch, q.shape[0])) for i in range(0, q.shape[0], batch)]
    if jobs > 1 and len(slices) > 1:
        with ThreadPoolExecutor(jobs) as pool:
            parts = list(pool.map(lambda sl: _step_batch(obs, params, noise, q, lam, sl, want_red), slices))
    else:
        parts = [_step_batch(obs, params, noise, q, lam, sl, want_red) for sl in slices]
    q_new = np.concatenate([p[0] for p in parts])
    lam_new = np.concatenate([p[1] for p in parts])
    st = State(*(np.concatenate([p[2][k] for p in parts]) for k in range(3)))
    red = {g: sum(p[4][g] for p in parts) for g in parts[0][4]}
    return q_new, lam_new, st, np.concatenate([p[3] for p in parts]), red


def group_sigma(obs: Observation, params: Params, st: State, used: dict | None = None) -> dict:
    """Dynamic variance adjustment (§2.3.5): σ_g² = RSS_g / (N_g − used_g), per sensor type.

    ``used`` is the degrees of freedom the q-phase took from each type (:func:`redundancy`);
    without it this is the plain RMS residual.
    """
    used = used or {}
    out = {}
    rp = params.gain * st.s + params.bias - obs.pots
    for kind in obs.groups:
        if kind == MARKERS:
            xb = np.einsum("tmij,mj->tmi", st.Rl, params.xyz) + st.pl
            r = (xb @ params.R.T + params.T - obs.markers)[obs.valid]
        else:
            r = rp[:, obs.kinds == kind]
        dof = max(r.size - used.get(kind, 0.0), 0.05 * r.size)
        out[kind] = float(np.sqrt(np.sum(r * r) / dof))
    return out


def pot_sigmas(obs: Observation, sigma: dict) -> np.ndarray:
    """σ of each pot from its type's σ: (P,)."""
    return np.array([sigma[k] for k in obs.kinds], dtype=float)
