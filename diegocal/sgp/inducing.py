"""Inducing inputs for sparse inference: greedy conditional-variance selection, grown until the
inducing-point approximation misses almost none of the GP's prior variance.

The DTC/VFE approximation (:class:`~diegocal.sgp.blocks.SparseBlock`) replaces the GP's covariance
``K_nn`` by ``Q = K_nm K_mm⁻¹ K_mn``. What it leaves out at sample i is the conditional variance
``d_i = k(u_i, u_i) − Q_ii`` of the GP at u_i given its values at the inducing inputs; Titsias's
bound subtracts ``Σ d_i / (2 σ_v²)`` for it. When the mean of ``d_i`` is small against the noise
variance σ_v², the approximate posterior is close to the exact one (Burt, Rasmussen & van der
Wilk, "Convergence of sparse variational inference in Gaussian process regression", JMLR 2020,
who bound the KL divergence between them by this trace term).

So the inducing inputs are chosen for that quantity: the greedy conditional-variance selection
that Burt et al. use to initialise inducing inputs, a partial pivoted Cholesky factorisation of
``K_nn`` (Harbrecht, Peters & Schneider 2012): each step takes the training input of largest
``d_i`` and updates every ``d`` in O(N M). It stops as soon as ``mean(d) ≤ tolerance · σ_v²``
(or at ``max_points``). Unlike k-means on the inputs, it sees the kernel: inputs along which the
length-scale is short get points densely, inputs the GP ignores none, and an output whose GP is
switched off (σ_z at its floor) needs a single point.

Why this replaced 300 k-means centres (issue #14): on the 3-link arm with a hidden cable friction on
joint 3 (4,000 samples), joint 3's GP has a length-scale of 0.15 training stds in its velocity (the
friction's sign change); 300 k-means centres in the 9 standardised inputs left a mean missed
variance of 0.9 σ_v² per sample, and the held-out nMSE rose from the exact posterior's 0.0086 to
0.017-0.038 (by k-means seed). Greedy selection reaches 0.01 σ_v² with about 400 points and
predicts as the exact posterior does.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Stop when the mean missed prior variance per sample is at most this fraction of σ_v².
SPARSE_TOLERANCE = 0.01
#: At most this many inducing inputs per output (SGPOptions.n_inducing). The selection costs
#: O(pool · M²) and the posterior O(N M²). A smooth GP reaches the tolerance well below it (the
#: issue #14 arm's friction GP: 406 points at 4,000 samples, 577 at 20,000). A GP of length-scales
#: near the samples' spacing never does: on the scale bench's 20,000 samples joint 2's GP (ℓ
#: 0.01-0.04 input stds) took 1,519 points, or all 2,000 on a log 5 samples longer (missed
#: variance 0.15 σ_v² there), and predicted the test run as PR does with 1,000 points or 2,000
#: (nMSE 4.191e-5 and 4.198e-5 against PR's 4.189e-5; on the longer log 4.190e-5 and 4.189e-5),
#: while 2,000 cost 28.3 and 31.9 CPU-s a fit against 24.1 and 25.3.
MAX_POINTS = 1000
#: At most this many training inputs are candidates (a random subset beyond): the selection costs
#: O(pool · M²), and the mean missed variance of a random pool estimates that of all samples.
POOL = 8000


@dataclass(frozen=True)
class Inducing:
    """Inducing inputs of one output.

    Attributes
    ----------
    points : (M, p) inducing inputs (rows of the training inputs, the estimator's scaled units)
    gap : mean missed prior variance per candidate sample, in units of σ_v² (the stopping rule)
    """

    points: np.ndarray
    gap: float


def greedy_inducing(
    kernel,
    theta: np.ndarray,
    U: np.ndarray,
    noise_var: float,
    *,
    tolerance: float = SPARSE_TOLERANCE,
    max_points: int = MAX_POINTS,
    pool: int = POOL,
    rng: np.random.Generator | None = None,
) -> Inducing:
    """Greedy conditional-variance inducing inputs for ``kernel`` with log-parameters ``theta``.

    Parameters
    ----------
    kernel : :class:`~diegocal.sgp.kernels.Kernel`
    theta : (n_params,) the kernel's log-parameters
    U : (N, p) training inputs
    noise_var : σ_v², the output's noise variance (y's unit squared)
    tolerance : stop when mean(k(u, u) − Q(u, u)) ≤ tolerance · σ_v²
    max_points : the most inducing inputs (a cap on cost: the selection is O(pool · M²) and the
        posterior O(N M²))
    pool : candidates: all N inputs, or a random subset of this many (``rng``)
    """
    U = np.asarray(U, float)
    cand = U
    if len(U) > pool:
        rng = rng or np.random.default_rng(0)
        cand = U[np.sort(rng.choice(len(U), pool, replace=False))]
    N = len(cand)
    limit = int(min(max(max_points, 1), N))
    d = np.array(kernel.diag(cand, theta), dtype=float)  # conditional variance given no point
    L = np.zeros((N, limit))  # partial pivoted Cholesky factor of K(cand, cand)
    chosen = []
    target = tolerance * noise_var
    while len(chosen) < limit and (not chosen or d.mean() > target):
        m = len(chosen)
        i = int(np.argmax(d))  # ties: the first (deterministic)
        if d[i] <= 0.0:
            break
        col = kernel(cand, cand[i : i + 1], theta)[:, 0]
        if m:
            col -= L[:, :m] @ L[i, :m]
        L[:, m] = col / np.sqrt(d[i])
        d -= L[:, m] ** 2
        np.maximum(d, 0.0, out=d)
        d[i] = 0.0
        chosen.append(i)
    return Inducing(cand[np.array(chosen, dtype=int)], float(d.mean() / noise_var))
