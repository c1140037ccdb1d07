"""STAC p-phase: sensor parameters in closed form with the joint angles fixed (thesis §2.3.1-2.3.2).

* mocap frame (R, T0) by Procrustes / Kabsch (eq. 2.13-2.16). The thesis's eq. (2.15),
  ``R = sign(det Σ) V Uᵀ``, is not a reflection guard (det Σ ≥ 0 always: Σ holds singular
  values). We use the standard Kabsch form ``R = V diag(1, 1, det(V Uᵀ)) Uᵀ``, which returns
  the best proper rotation even when the data would prefer a reflection.
* marker positions d_m: mean of the observed marker in its link frame (eq. 2.17); NaN
  (occluded) samples are skipped; with robust weights the mean is weighted.
* pot gain/bias: linear least squares on the transmission s(q) (eq. 2.18-2.20), bias only for
  encoders (gain fixed at 1). Standard errors from the normal equations and the residual sigma.

The two marker blocks are alternated a few times (each is the exact minimiser given the other).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from diegocal.errors import NumericalError
from diegocal.stac.model import Observation, Params, State

#: Frames per chunk of the p-phase's sums over frames: its temporaries stay small on long logs.
CHUNK = 4096


@dataclass(frozen=True)
class PhaseResult:
    """θ after a p-phase and the standard errors: gain, bias (P,), xyz (M, 3)."""

    params: Params
    se: dict


def kabsch(xb: np.ndarray, x: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Weighted rigid fit x ≈ R xb + T (eq. 2.13-2.16, reflection-safe Kabsch form).

    xb, x : (N, 3) points in base and mocap frames, m; w : (N,) non-negative weights.
    Returns R (3, 3) and T (3,).
    """
    sw = w.sum()
    if sw <= 0:
        raise NumericalError("Procrustes: no valid marker sample (all occluded?)")
    cb = (w[:, None] * xb).sum(0) / sw  # eq. 2.13
    cx = (w[:, None] * x).sum(0) / sw
    S = ((xb - cb) * w[:, None]).T @ (x - cx)  # eq. 2.14: U Σ Vᵀ
    R = _proper_rotation(S)
    return R, cx - R @ cb  # eq. 2.16


def _proper_rotation(S: np.ndarray) -> np.ndarray:
    """argmax_R tr(R S) over rotations for the 3 x 3 cross-covariance S = Σ w xb xᵀ (eq. 2.14)."""
    U, _, Vt = np.linalg.svd(S)
    d = np.sign(np.linalg.det(Vt.T @ U.T)) or 1.0
    return Vt.T @ np.diag([1.0, 1.0, d]) @ U.T  # replaces eq. 2.15 (see module docstring)


def markers_fit(obs: Observation, st: State, params: Params, w: np.ndarray, inner: int = 4):
    """Alternate Procrustes (R, T0) and marker means d (eq. 2.13-2.17) a few times; returns
    (R, T, d, d_se).

    Both steps are linear in the data given (R, d), so one pass over the frames collects their
    weighted moments per marker (with x_c = x − c_x, c_x the weighted centroid of the markers):
    ``Σ w``, ``G = Σ w h_r``, ``Σ w h_p``, ``C = Σ w h_r ⊗ x_c``, ``D = Σ w h_p x_cᵀ``,
    ``K = Σ w h_rᵀ h_p``; the alternation then costs nothing per frame:
    c_b = Σ_m (G_m d_m + Σ w h_p) / Σ w, S = Σ_m (C_m · d_m + D_m) (eq. 2.13-2.14; Σ w x_c = 0),
    and d_m = (Σ_ik R_ki C_m,i·k + G_mᵀ c_b − K_m) / Σ w (eq. 2.17, with T0 = c_x − R c_b).
    """
    sw = w.sum(0)  # (M,)
    if sw.sum() <= 0:
        raise NumericalError("Procrustes: no valid marker sample (all occluded?)")
    chunks = [slice(i, i + CHUNK) for i in range(0, w.shape[0], CHUNK)]  # the frames' moments, a chunk at a time

    # the markers of each chunk where they weigh, else 0 (occluded: NaN, never picked by where)
    seen = [np.where(w[sl, :, None] > 0, obs.markers[sl], 0.0) for sl in chunks]
    cx = sum(np.einsum("tm,tmk->k", w[sl], x) for sl, x in zip(chunks, seen, strict=True)) / sw.sum()
    M = w.shape[1]
    G, Pm, C, D, K = np.zeros((M, 3, 3)), np.zeros((M, 3)), np.zeros((M, 9, 3)), np.zeros((M, 3, 3)), np.zeros((M, 3))
    for sl, x in zip(chunks, seen, strict=True):
        Rl, pl, wc = st.Rl[sl], st.pl[sl], w[sl]
        xc = (x - cx) * wc[..., None]  # weighted, centred
        G += np.einsum("tm,tmij->mij", wc, Rl)
        Pm += np.einsum("tm,tmi->mi", wc, pl)
        C += np.matmul(Rl.reshape(-1, M, 9).transpose(1, 2, 0), xc.transpose(1, 0, 2))
        D += np.matmul(pl.transpose(1, 2, 0), xc.transpose(1, 0, 2))
        K += np.einsum("tm,tmj->mj", wc, np.einsum("tmij,tmi->tmj", Rl, pl))
    C = C.reshape(M, 3, 3, 3)
    R, d = params.R, params.xyz
    for _ in range(inner):
        cb = (np.einsum("mij,mj->i", G, d) + Pm.sum(0)) / sw.sum()  # eq. 2.13
        R = _proper_rotation(np.einsum("mijk,mj->ik", C, d) + D.sum(0))  # eq. 2.14-2.15
        d_new = (np.einsum("mijk,ki->mj", C, R) + np.einsum("mij,i->mj", G, cb) - K) / np.maximum(sw, 1e-300)[:, None]
        d = np.where(sw[:, None] > 0, d_new, d)  # eq. 2.17; a marker with no weight keeps its position
    T = cx - R @ cb  # eq. 2.16
    # standard error of each mean from the spread of the marker in its link frame
    ss = np.zeros((M, 3))
    for sl, x in zip(chunks, seen, strict=True):
        y = ((x - cx).reshape(-1, 3) @ R).reshape(x.shape)  # R⁻¹ (x − c_x): one product, not one per frame
        local = np.einsum("tmji,tmj->tmi", st.Rl[sl], y + cb - st.pl[sl])  # h_rᵀ (R⁻¹ (x − T0) − h_p)
        ss += (w[sl, :, None] * (local - d) ** 2).sum(0)
    n = (w > 0).sum(0)
    dof = np.where(n > 1, sw * (n - 1) / np.maximum(n, 1), np.nan)[:, None]  # NaN: a marker seen < 2 times
    var = ss / np.maximum(dof, 1e-300)
    se = np.sqrt(var * (w**2).sum(0)[:, None]) / sw[:, None]
    return R, T, d, se


def pots_fit(obs: Observation, st: State, w: np.ndarray, bias0: np.ndarray, gain0: np.ndarray | None = None):
    """Eq. 2.18-2.20 by weighted linear least squares per pot; w (T, P) robust weights.

    Returns gain, bias, gain_se, bias_se (P,). Encoders: gain 1, bias = mean(p − s). Pots in
    ``obs.fixed_bias`` (gauge, see Observation._gauge_biases) keep ``bias0`` and fit the gain only;
    pots in ``obs.fixed_gain`` (unobservable, see Observation.check_observable) keep ``gain0`` and
    ``bias0`` (standard errors NaN).
    SE: σ̂² (Xᵀ W X)⁻¹ with σ̂² = Σ w r² / (N − k), the usual LS covariance with q held fixed.
    """
    P = obs.n_pots
    s, p = st.s, obs.pots
    gain = np.ones(P) if gain0 is None else np.where(obs.fixed_gain, gain0, 1.0)
    bias = bias0.astype(float).copy()
    gse, bse = np.full(P, np.nan), np.full(P, np.nan)
    # the weighted sums of every pot at once (T, P) -> (P,): Σw, Σws, Σws², Σwp, Σwsp
    ws = w * s
    sw, sws, swss, swp, swsp = w.sum(0), ws.sum(0), (ws * s).sum(0), (w * p).sum(0), (ws * p).sum(0)
    encoder = obs.kinds == "encoder"
    fixed = obs.fixed_gain  # gain and bias nominal
    gain_only = obs.fixed_bias & ~fixed & ~encoder  # bias held: the gain alone
    enc = ~fixed & ~obs.fixed_bias & encoder  # gain 1: the bias alone
    both = ~fixed & ~obs.fixed_bias & ~encoder  # gain and bias (eq. 2.18-2.20)
    gain[gain_only] = (swsp - bias0 * sws)[gain_only] / swss[gain_only]
    bias[enc] = (swp - sws)[enc] / sw[enc]
    N = np.stack([np.stack([swss, sws], -1), np.stack([sws, sw], -1)], -2)[both]  # Xᵀ W X, X = [s, 1]
    if N.size:
        bad = np.linalg.cond(N) > 1e12
        if bad.any():
            raise NumericalError(
                f"pot {obs.pot_names[np.flatnonzero(both)[np.argmax(bad)]]!r}: its transmission does not vary in "
                "the log; record motion of its joint(s) to calibrate it"
            )
        gain[both], bias[both] = np.linalg.solve(N, np.stack([swsp, swp], -1)[both, :, None])[..., 0].T
    r = p - gain * s - bias
    rss = (w * r * r).sum(0)
    gse[gain_only] = np.sqrt(rss / np.maximum(sw - 1, 1) / swss)[gain_only]
    bse[enc] = np.sqrt(rss / np.maximum(sw - 1, 1) / sw)[enc]
    if N.size:
        var = (rss / np.maximum(sw - 2, 1))[both, None] * np.diagonal(np.linalg.inv(N), axis1=1, axis2=2)
        gse[both], bse[both] = np.sqrt(var).T
    return gain, bias, gse, bse


def p_phase(obs: Observation, st: State, params: Params, w_pots: np.ndarray, w_markers: np.ndarray) -> PhaseResult:
    """All sensor parameters at fixed q (thesis eq. 2.6: independent sub-problems per sensor)."""
    R, T, d, dse = markers_fit(obs, st, params, w_markers)
    gain, bias, gse, bse = pots_fit(obs, st, w_pots, params.bias, params.gain)
    return PhaseResult(Params(gain, bias, d, R, T), {"gain": gse, "bias": bse, "xyz": dse})
