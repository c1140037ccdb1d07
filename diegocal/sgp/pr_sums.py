"""PR (no GP on any output) fitted from per-block sums of the training features, never holding
them whole: a long log's regressor is built a chunk of samples at a time (issue #33).

Without a GP every output's covariance block is σ_v,j² I, and everything the posterior of
:mod:`diegocal.sgp.gp` needs from the N training rows is, per output j, the Gram matrix of
``[F_j, y_j]`` (thesis eq. 3.13-3.20 through the Woodbury form there):

.. math::
    M = \\Sigma_w^{-1} + \\sum_j F_j^T F_j / \\sigma_{v,j}^2, \\quad
    \\hat w = M^{-1} \\sum_j F_j^T y_j / \\sigma_{v,j}^2, \\quad
    y^T K^{-1} y = \\sum_j (y_j^T y_j - y_j^T F_j \\hat w) / \\sigma_{v,j}^2

and W's cluster-robust covariance (:func:`~diegocal.sgp.gp.robust_w_cov`) needs the same Gram
matrices per contiguous time block: its block score is ``s_g = Σ_j (F_jᵀ y_j − F_jᵀ F_j ŵ)_g /
σ_v,j²``. :class:`GramSums` accumulates them chunk by chunk ((m+1)² numbers per output and
block); :func:`posterior_from_sums` gives the posterior :func:`~diegocal.sgp.gp.fit_posterior`
gives on the whole arrays (the same numbers up to the order of the sums).
"""

from __future__ import annotations

import copy

import numpy as np
from scipy.linalg import cho_solve

from diegocal.sgp.blocks import LOG_2PI, ExactBlock, cholesky
from diegocal.sgp.gp import ROBUST_BLOCKS, Hyperparameters, Posterior


class GramSums:
    """Per contiguous time block and output, the Gram matrix of [F_j, y_j] over its rows.

    The blocks split the N rows as ``np.array_split(np.arange(N), min(ROBUST_BLOCKS, N))`` does
    (those of :func:`~diegocal.sgp.gp.robust_w_cov`). Rows are added in order, in chunks of any
    size (:meth:`add`).
    """

    def __init__(self, N: int, n: int, m: int):
        self.N, self.n, self.m = N, n, m
        g = min(ROBUST_BLOCKS, N)
        self.edges = np.array([0, *np.cumsum([p.size for p in np.array_split(np.arange(N), g)])])
        self.G = np.zeros((g, n, m + 1, m + 1))
        self.rows = 0

    def add(self, F: np.ndarray, Y: np.ndarray) -> None:
        """The next rows: F (c, n, m) features and Y (c, n) outputs, in time order."""
        start, c = self.rows, len(Y)
        for g in range(len(self.G)):
            lo, hi = max(self.edges[g], start), min(self.edges[g + 1], start + c)
            if lo >= hi:
                continue
            for j in range(self.n):
                Z = np.column_stack([F[lo - start : hi - start, j], Y[lo - start : hi - start, j]])
                self.G[g, j] += Z.T @ Z
        self.rows += c

    def feature_rms(self) -> np.ndarray:
        """(m,) each feature column's RMS over samples and outputs (the estimator's scaling)."""
        sq = np.einsum("gjmm->m", self.G[:, :, : self.m, : self.m])
        return np.sqrt(sq / (self.N * self.n))

    def scaled(self, f_scale: np.ndarray) -> GramSums:
        """The sums of the features divided column-wise by ``f_scale`` (m,)."""
        s = np.concatenate([f_scale, [1.0]])
        out = copy.copy(self)
        out.G = self.G / np.outer(s, s)
        return out


def posterior_from_sums(sums: GramSums, U: np.ndarray, hp: Hyperparameters, robust: bool = True) -> Posterior:
    """:func:`~diegocal.sgp.gp.fit_posterior` for outputs without a GP, from ``sums`` (of the
    scaled features, all rows added); U (N, p) the scaled inputs (a block without a GP keeps their count)."""
    n, m, N = sums.n, sums.m, sums.N
    noise = np.exp(2.0 * hp.log_sigma_v)
    sw2 = np.exp(2.0 * hp.log_sigma_w)
    total = sums.G.sum(axis=0)  # (n, m+1, m+1)
    Gff, Gfy, yy = total[:, :m, :m], total[:, :m, m], total[:, m, m]
    blocks = []
    for j in range(n):
        blk = ExactBlock(None, U, np.zeros(0), float(noise[j]))
        blk.finalize(None, np.empty((0, m)))  # PR predicts from ŵ alone: no α, F_j's width only
        blocks.append(blk)
    B = np.einsum("jab,j->ab", Gff, 1.0 / noise)
    b = Gfy.T @ (1.0 / noise)
    if m:
        LM, _ = cholesky(B + np.eye(m) / sw2, "parameter precision Σ_w⁻¹ + Fᵀ A⁻¹ F")
        w = cho_solve((LM, True), b, check_finite=False)
    else:
        LM, w = None, np.zeros(0)
    y_alpha = float(np.sum((yy - Gfy @ w if m else yy) / noise))
    logdet = float(N * np.sum(np.log(noise)))
    if m:
        logdet += m * np.log(sw2) + 2.0 * np.sum(np.log(np.diag(LM)))
    ll = -0.5 * y_alpha - 0.5 * logdet - 0.5 * N * n * LOG_2PI
    w_cov_robust = None
    if robust and m:
        s = np.einsum("gja,j->ga", sums.G[:, :, :m, m] - sums.G[:, :, :m, :m] @ w, 1.0 / noise)
        g = len(s)
        meat = s.T @ s * g / max(g - 1, 1)
        m_inv = cho_solve((LM, True), np.eye(m), check_finite=False)
        w_cov_robust = m_inv @ meat @ m_inv
    return Posterior(blocks, w, LM, noise, ll, w_cov_robust)
