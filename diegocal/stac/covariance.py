"""Standard errors of θ that say what the data say: a sandwich over contiguous blocks of frames.

With the joint angles q_t of every frame profiled out (the Schur complement of eq. 2.21, as the
joint step forms it, :mod:`.joint_step`), θ = [gain, bias, d_1:M, ω, T0] is an M-estimate whose
per-frame score is

.. math:: g_t = (J_{θ,t} - J_{q,t} H_t^{-1} B_t)^T W_t z_t ,  \\qquad
          A = \\sum_t J_{θ,t}^T W_t J_{θ,t} - B_t^T H_t^{-1} B_t ,

z_t the frame's standardised residuals, H_t = J_qᵀ W J_q, B_t = J_qᵀ W J_θ. The model-based
covariance A⁻¹ holds when the residuals are independent from frame to frame with the σ of their
type; at 100 Hz they are not (mocap reconstruction smooths, a tracked q carries its errors from
frame to frame), and one σ per type hides a worse camera axis. The cluster-robust (sandwich)
covariance

.. math:: V = \\frac{G}{G-1} A^{-1} \\Big(\\sum_b s_b s_b^T\\Big) A^{-1}, \\qquad s_b = \\sum_{t \\in b} g_t

over G contiguous blocks of frames (:data:`BLOCKS`, each much longer than the residuals'
correlation time) holds either way. Its variances are estimated from G block sums (noisier than
A⁻¹'s), and with few blocks it errs low, so a parameter's standard error is the larger of the two:
the model-based one when the data are as the model says, the sandwich when they are not.

A is summed over an evenly spaced subset of at most ``max_frames`` frames, scaled (as the joint
step does, to keep the dense per-frame Jacobians small); the scores over every frame (from the
structure of J_θ, without forming it).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from diegocal.stac.joint_step import _theta_rows, _times_q, free_mask, pick, reduced_matrix
from diegocal.stac.model import Observation, Params, State
from diegocal.stac.qphase import Noise, block_solve, damped, normal_equations
from diegocal.terms import CORRELATED, correlated_pairs

#: Contiguous blocks of frames the sandwich's meat is summed over (fewer on short logs: a block is
#: at least MIN_BLOCK frames). 40 blocks of a 30-s log at 100 Hz are 0.75 s each, many times the
#: correlation time of the tracking residuals (tens of ms).
BLOCKS = 40
MIN_BLOCK = 10


@dataclass(frozen=True)
class Covariance:
    """θ's covariance over the free entries (``free`` (Nθ,) bool of θ = [gain (P), bias (P),
    d (3M), ω (3), T (3)]): ``model`` = A⁻¹, ``robust`` the block sandwich, ``blocks`` G.

    :meth:`se` gives the standard errors the calibration reports; :meth:`correlations` the pairs
    that trade off."""

    free: np.ndarray
    model: np.ndarray
    robust: np.ndarray
    blocks: int
    n_pots: int
    n_markers: int

    @property
    def reported(self) -> np.ndarray:
        """The covariance the standard errors come from: the sandwich, its diagonal floored at
        the model's (module docstring), the correlations the sandwich's."""
        d = standard_errors(self.model, self.robust)
        c = self.correlation()
        return c * np.outer(d, d)

    def correlation(self) -> np.ndarray:
        d = np.sqrt(np.maximum(np.diag(self.robust), 1e-300))
        c = self.robust / np.outer(d, d)
        np.fill_diagonal(c, 1.0)
        return np.clip(c, -1.0, 1.0)

    def se(self) -> dict:
        """``{"gain", "bias" (P,), "xyz" (M, 3), "xyz_cov" (2, 3M, 3M)}``, NaN for the entries held
        fixed; ``xyz_cov``: the markers' coordinates' covariance, reported and model-based (what a
        function of them, a slip's move from one marker to another, needs: its ± is floored at the
        model-based one, as each parameter's is)."""
        P, M = self.n_pots, self.n_markers
        sd = np.full(self.free.size, np.nan)
        sd[self.free] = np.sqrt(np.diag(self.reported))
        xyz = slice(2 * P, 2 * P + 3 * M)
        cov = np.full((2, self.free.size, self.free.size), np.nan)
        cov[np.ix_((0, 1), self.free, self.free)] = self.reported, self.model
        return {"gain": sd[:P], "bias": sd[P : 2 * P], "xyz": sd[xyz].reshape(M, 3), "xyz_cov": cov[:, xyz, xyz]}

    def correlations(self, labels, threshold: float = CORRELATED) -> list[tuple[str, str, float]]:
        """(label a, label b, ρ) of the free gains, biases and marker coordinates whose estimates
        correlate by at least ``threshold`` (``labels`` (Nθ,) names θ's entries; ω, T left out)."""
        P, M = self.n_pots, self.n_markers
        idx = np.flatnonzero(self.free)
        keep = idx < 2 * P + 3 * M
        return correlated_pairs(self.correlation()[np.ix_(keep, keep)], [labels[i] for i in idx[keep]], threshold)


def covariance(
    obs: Observation,
    params: Params,
    noise: Noise,
    q: np.ndarray,
    batch: int = 250,
    max_frames: int = 500,
    blocks: int = BLOCKS,
    st: State | None = None,
) -> Covariance:
    """θ's model-based and block-sandwich covariances at a fit (module docstring); q (T, n) the
    tracked joint angles, ``noise`` the σ per type the fit ended with; ``st``, the State at q,
    lends its kept linearisation (:func:`~diegocal.stac.qphase.normal_equations`)."""
    P, M = obs.n_pots, obs.n_markers
    # the scores' block sums, not every frame's scores (T, Nθ): 1.2 kB a frame on diego (issue #33)
    A, sums = information(obs, params, noise, q, batch, max_frames, st, block_length(q.shape[0], blocks))
    free = free_mask(obs)
    Af = 0.5 * (A + A.T)[np.ix_(free, free)]
    Af = Af + 1e-9 * max(np.trace(Af), 1.0) / max(free.sum(), 1) * np.eye(free.sum())
    model = np.linalg.inv(Af)
    robust, G = sandwich(model, sums[:, free])
    return Covariance(free, model, robust, G, P, M)


def block_length(T: int, blocks: int = BLOCKS) -> int:
    """Frames per block of the sandwich: T frames cut into ``blocks`` contiguous blocks of at least
    MIN_BLOCK frames (the last one holds the rest)."""
    return max(MIN_BLOCK, T // max(blocks, 1))


def block_sandwich(bread_inv: np.ndarray, scores: np.ndarray, blocks: int = BLOCKS) -> tuple[np.ndarray, int]:
    """The cluster-robust covariance (k, k) ``G/(G−1) A⁻¹ (Σ_b s_b s_bᵀ) A⁻¹`` and G, for A⁻¹
    ``bread_inv`` (k, k) and per-frame scores (T, k) (rows of frames outside the fit zero), the
    frames cut into ``blocks`` blocks (:func:`block_length`)."""
    T = scores.shape[0]
    return sandwich(bread_inv, np.add.reduceat(scores, np.arange(0, T, block_length(T, blocks)), axis=0))


def sandwich(bread_inv: np.ndarray, sums: np.ndarray) -> tuple[np.ndarray, int]:
    """:func:`block_sandwich` from the scores' block sums s_b (blocks, k); G counts the non-zero ones."""
    G = int(np.count_nonzero(np.any(sums != 0.0, axis=1)))
    meat = sums.T @ sums * (G / max(G - 1, 1))
    robust = bread_inv @ meat @ bread_inv
    return 0.5 * (robust + robust.T), G


def standard_errors(model: np.ndarray, robust: np.ndarray) -> np.ndarray:
    """Per parameter the larger of the model-based and the sandwich standard error (module
    docstring)."""
    return np.sqrt(np.maximum(np.diag(robust), np.diag(model)))


def information(
    obs: Observation,
    params: Params,
    noise: Noise,
    q: np.ndarray,
    batch: int = 250,
    max_frames: int = 500,
    st: State | None = None,
    length: int | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """A (Nθ, Nθ), the information of θ with q profiled out (from every ``stride``-th frame,
    scaled), and the profiled scores g_t (T, Nθ) of every frame (module docstring; sign: minus);
    with ``length``, their sums over blocks of that many frames instead (⌈T / length⌉, Nθ), added
    a block at a time (:class:`_BlockSums`: the same bits as :func:`block_sandwich`'s)."""
    T = q.shape[0]
    N = 2 * obs.n_pots + 3 * obs.n_markers + 6
    stride = max(1, -(-T // max_frames))
    scores = np.zeros((T, N)) if length is None else _BlockSums(T, N, length)
    picked = []  # what A needs of the frames t ≡ 0 (mod stride), summed after the loop
    for start in range(0, T, batch):
        sl = slice(start, min(start + batch, T))
        H, g, _, (s, Rl, pl), _, ex = normal_equations(obs, params, noise, q, sl, want_red=False, st=st)
        Hd = damped(H, np.zeros(g.shape[0]), inplace=True)  # the tiny ridge only: joints no sensor sees
        v = block_solve(Hd, g)  # H⁻¹ J_qᵀ W z
        # J_θᵀ W (J_q H⁻¹ J_qᵀ W z − z) per frame: minus the profiled score (its sign is immaterial)
        rows = _theta_rows(obs, params, noise, s, Rl, pl, _times_q(obs, params, noise, ex, v), ex["x"])
        if length is None:
            scores[sl] = rows
        else:
            scores.add(rows)
        picked.append(pick(Hd, ex, s, Rl, pl, np.flatnonzero(np.arange(sl.start, sl.stop) % stride == 0)))
    return stride * reduced_matrix(obs, params, noise, picked), scores if length is None else scores.done()


class _BlockSums:
    """The scores' sums over blocks of ``length`` frames (blocks, k), made as the frames come in
    order: each block's rows are held until it is complete, then summed by ``np.add.reduceat`` on
    them alone (the same bits as over every frame's scores: a segment's sum does not depend on the
    rows around it). Holds one block and a batch of rows, not every frame's (T, k)."""

    def __init__(self, T: int, k: int, length: int):
        self.sums, self.length = np.zeros((-(-T // length), k)), length
        self.held, self.at = np.zeros((0, k)), 0  # rows of the blocks not yet summed, the first one's frame

    def add(self, rows: np.ndarray) -> None:
        """The next frames' rows (B, k)."""
        rows = np.concatenate([self.held, rows]) if len(self.held) else rows
        whole = len(rows) // self.length * self.length
        self.done(rows[:whole])
        self.held = rows[whole:].copy()

    def done(self, rows: np.ndarray | None = None) -> np.ndarray:
        """Sum ``rows`` (whole blocks from the block in hand; default: what is held, the last one,
        shorter); returns the sums."""
        rows = self.held if rows is None else rows
        if len(rows):
            b = self.at // self.length
            self.sums[b : b + -(-len(rows) // self.length)] = np.add.reduceat(
                rows, np.arange(0, len(rows), self.length), axis=0
            )
            self.at += len(rows)
        return self.sums


def theta_labels(obs: Observation) -> list[str]:
    """Names of θ's entries (Nθ,): ``<pot>.gain``, ``<pot>.bias``, ``<marker>.x|y|z``, then ω, T."""
    out = [f"{n}.gain" for n in obs.pot_names] + [f"{n}.bias" for n in obs.pot_names]
    out += [f"{m}.{a}" for m in obs.marker_names for a in "xyz"]
    return out + ["mocap.rx", "mocap.ry", "mocap.rz", "mocap.x", "mocap.y", "mocap.z"]
