"""Each sensor predicted from all the others: leave one sensor out, linearised at the tracked q.

At a frame's joint angles q (tracked from every sensor), the observation Jacobian J (R × n: P
pot rows, then 3 per marker) and the weighted projector K = (JᵀWJ + D)⁻¹ JᵀW (W = diag(1/σ²),
thesis eq. 2.22-2.23) give each reading's *deleted residual*: its residual had q been tracked
from the frame's other readings only, exact for the linearised frame. For a pot it is
(r − J K r) / (1 − h), h the diagonal of J K; for a marker (I − H_m)⁻¹ (r_m − (J K r)_m), H_m
its 3 × 3 block of J K. A reading that alone fixes a direction of q (h = 1) has none: NaN.

A reading's own residual rewards a model for following it (a rotary pot that largely fixes its
joint's q has a small residual whatever its transfer curve); its deleted residual is a held-out
prediction by the other sensors. ``diegocal predict --from others`` reports it, and ``diagnose``
scores a kinematic model by it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from diegocal.parallel import one_blas_thread, thread_map
from diegocal.stac.model import MARKERS, Observation

#: Frames per batch when the Jacobians are evaluated: a batch's J and K are 2 x BATCH x R x n
#: floats (17 MB on Diego San), whatever the log's length.
BATCH = 250


@dataclass(frozen=True)
class FrameProjection:
    """The linearised observation of every frame at q (module docstring).

    J : (T, R, n); K : (T, n, R); w : (T, R) the weights 1/σ² (0 where occluded); s : (T, P) the
    sensed lengths or angles; Rl : (T, M, 3, 3) the markers' link rotations; sigma_p : (P,) the
    pots' σ used; D : (T, n) the tiny diagonal that keeps JᵀWJ invertible (unobserved joints);
    H : (T, n, n) JᵀWJ + D, kept in place of K where the caller forms its inverse itself (else None)
    """

    J: np.ndarray
    K: np.ndarray | None
    w: np.ndarray
    s: np.ndarray
    Rl: np.ndarray
    sigma_p: np.ndarray
    D: np.ndarray
    H: np.ndarray | None = None


def sigma_of(calibration) -> dict:
    """σ per sensor type of a calibration (its ``sigma_by_group``, else its pots' or markers' σ)."""
    sig = dict(calibration.sigma_by_group)
    sig.setdefault(MARKERS, calibration.sigma_markers)
    return {**{k: calibration.sigma_pots for k in ("rotary", "linear", "tendon", "encoder")}, **sig}


def frame_projection(obs: Observation, params, sigma: dict, q: np.ndarray) -> FrameProjection:
    """:class:`FrameProjection` at joint angles q (T, n) with ``sigma``: σ per sensor type
    (:func:`sigma_of`), in the sensors' units. Built BATCH frames at a time (each frame's J and K
    depend on that frame alone), so that only the result grows with the log."""
    T, P, M, n = obs.n_frames, obs.n_pots, obs.n_markers, q.shape[1]
    R = P + 3 * M
    out = FrameProjection(
        np.empty((T, R, n)),
        np.empty((T, n, R)),
        np.empty((T, R)),
        np.empty((T, P)),
        np.empty((T, M, 3, 3)),
        pot_sigmas(obs, sigma),
        np.empty((T, n)),
    )
    for sl, part in frame_batches(obs, params, sigma, q):
        for f in ("J", "K", "w", "s", "Rl", "D"):
            getattr(out, f)[sl] = getattr(part, f)
    return out


def frame_batches(obs: Observation, params, sigma: dict, q: np.ndarray, batch: int = BATCH, solve: bool = True):
    """(frames, :class:`FrameProjection` of those frames) for each ``batch`` of frames in turn:
    :func:`frame_projection` without holding the whole log's (``solve`` False: K None and H kept,
    for a caller that forms (JᵀWJ + D)⁻¹ itself)."""
    for sl in frame_slices(obs.n_frames, batch):
        yield sl, batch_projection(obs, params, sigma, q, sl, solve)


def frame_slices(T: int, batch: int = BATCH) -> list[slice]:
    """The frames 0..T-1 in consecutive slices of ``batch`` (the last one shorter)."""
    return [slice(i, min(i + batch, T)) for i in range(0, T, batch)]


def pot_sigmas(obs: Observation, sigma: dict) -> np.ndarray:
    """The pots' σ (P,) as the projection weighs them (floored: :func:`_sigmas`)."""
    return _sigmas(obs, sigma)[0]


def _sigmas(obs: Observation, sigma: dict) -> tuple[np.ndarray, float]:
    """The pots' σ (P,) as weighed and the markers' σ, from σ per sensor type."""
    sigma_p = np.array([sigma[k] for k in obs.kinds], float)
    sig_x = float(sigma.get(MARKERS, 1.0))  # a log without markers: no marker row is weighed
    # a pot type fitted exactly (one pot per joint, its σ collapsed) pins its joints, but no
    # weight may swamp the others' in floating point
    floor = 1e-3 * float(np.max(np.concatenate([sigma_p, [sig_x / 0.1]])))
    return np.maximum(sigma_p, floor), sig_x


def batch_projection(
    obs: Observation, params, sigma: dict, q: np.ndarray, sl: slice, solve: bool = True
) -> FrameProjection:
    """:class:`FrameProjection` of the frames ``sl`` (thesis eq. 2.22-2.23 per frame)."""
    sigma_p, sig_x = _sigmas(obs, sigma)
    P, M, n = obs.n_pots, obs.n_markers, q.shape[1]
    B = len(range(*sl.indices(obs.n_frames)))
    J = np.zeros((B, P + 3 * M, n))
    s, ds, Rl, _, Jx = obs.evaluate(q[sl], params.xyz)
    J[:, :P] = params.gain[None, :, None] * ds
    J[:, P:] = np.einsum("ij,bmjn->bmin", params.R, Jx).reshape(B, 3 * M, n)
    w = np.zeros((B, P + 3 * M))
    w[:, :P] = 1.0 / sigma_p**2
    w[:, P:] = np.repeat(obs.valid[sl].astype(float), 3, axis=1) / sig_x**2
    JW = np.swapaxes(J, 1, 2) * w[:, None, :]
    H = JW @ J
    diag = np.einsum("bii->bi", H)
    D = 1e-9 * diag + 1e-12  # keeps unobserved joints' H invertible
    diag += D
    if solve:
        return FrameProjection(J, np.linalg.solve(H, JW), w, s, Rl, sigma_p, D)
    return FrameProjection(J, None, w, s, Rl, sigma_p, D, H)


def deleted_from_others(obs: Observation, params, sigma: dict, q: np.ndarray, r: np.ndarray, jobs: int = 1):
    """:func:`deleted_residuals` of the residuals r (T, R) at joint angles q (T, n), a BATCH of
    frames at a time, in ``jobs`` threads: the same numbers as ``deleted_residuals(
    frame_projection(...), r, P)`` without holding every frame's J and K (what ``predict --from
    others`` needs on a long log)."""
    T, P = obs.n_frames, obs.n_pots
    rp = np.empty((T, P))
    rm = np.empty((T, obs.n_markers, 3))

    def batch(sl: slice) -> None:
        rp[sl], rm[sl] = deleted_residuals(batch_projection(obs, params, sigma, q, sl), r[sl], P)

    with one_blas_thread():
        thread_map(batch, frame_slices(T, BATCH), jobs)
    return rp, rm


def deleted_residuals(proj: FrameProjection, r: np.ndarray, n_pots: int) -> tuple[np.ndarray, np.ndarray]:
    """Each reading's deleted residual (module docstring) from the residuals r (T, R) of the mapped
    rows: pots (T, P), markers (T, M, 3). J K r is zero where q solves this weighting's normal
    equations (the textbook r / (1 − h)); it is kept because a tracked q need not: a pot whose σ
    collapsed pinned its joint in the fit, whose own residual is then ~0, while the other sensors'
    pull on that joint is what its deleted residual is."""
    J, K = proj.J, proj.K
    a = np.einsum("trn,tn->tr", J, np.einsum("tnr,tr->tn", K, np.nan_to_num(r)))
    r = r - a
    P, T = n_pots, r.shape[0]
    M = (r.shape[1] - P) // 3
    h = np.einsum("tpn,tnp->tp", J[:, :P], K[:, :, :P])
    with np.errstate(divide="ignore", invalid="ignore"):
        rp = np.where(1.0 - h > 1e-12, r[:, :P] / (1.0 - h), np.nan)
    Jm = J[:, P:].reshape(T, M, 3, -1)
    Km = K[:, :, P:].reshape(T, -1, M, 3)
    A = np.eye(3) - np.einsum("tmin,tnmj->tmij", Jm, Km)
    rm = r[:, P:].reshape(T, M, 3)
    ok = np.isfinite(rm).all(-1) & (np.abs(np.linalg.det(A)) > 1e-12)
    out = np.full_like(rm, np.nan)
    out[ok] = np.linalg.solve(A[ok], rm[ok][..., None])[..., 0]
    return rp, out
