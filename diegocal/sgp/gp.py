"""SGP inference: marginal likelihood with analytic gradient, and the posterior (thesis §3.3.1).

Model for n outputs (joints) observed at N inputs, thesis eq. (3.1)-(3.7) with ``g = I``:

.. math::
    y_j = F_j W + z_j + v_j, \\quad W \\sim N(0, \\sigma_w^2 I_m),\\;
    z_j \\sim GP(0, k_j),\\; v_j \\sim N(0, \\sigma_{v,j}^2 I_N)

``W`` (m,) is shared by every output (it couples them); ``z_j`` are independent per output
(δ(i, j) in eq. 3.4). Stacking y (n·N,), its covariance is ``K = F Σ_w Fᵀ + blockdiag(A_j)`` with
``A_j = K_z,j + σ_v,j² I``. Never forming K, the Woodbury identity and the matrix-determinant
lemma give (R&W §2.7, generalised to a shared W):

.. math::
    M = \\Sigma_w^{-1} + \\sum_j F_j^T A_j^{-1} F_j, \\quad
    \\hat w = M^{-1} \\sum_j F_j^T A_j^{-1} y_j, \\quad
    \\alpha_j = A_j^{-1}(y_j - F_j \\hat w) = (K^{-1} y)_j

    \\log|K| = \\sum_j \\log|A_j| + m \\log \\sigma_w^2 + \\log|M|

so the cost is n Cholesky factorisations of N×N plus O(n N² m), not O((nN)³). Posterior mean and
variance at a query (eq. 3.8-3.20, marginalising W): with ``r = f_j(q) - F_j^T A_j^{-1} k_j(q)``,
``E = f_j(q) ŵ + k_j(q)^T α_j`` and ``V = k_j(q,q) - k_j(q)^T A_j^{-1} k_j(q) + r^T M^{-1} r``.

The thesis's printed likelihood (§3.3.4) is garbled (it uses σ_qd σ_dd⁻¹ σ_qdᵀ + σ_v as the
covariance of the data). We use the Gaussian marginal likelihood of y under the full covariance
K above, which is what eq. (3.13)-(3.15) define.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import blas, cho_solve, lapack, solve_triangular

from diegocal.errors import NumericalError
from diegocal.sgp.kernels import Kernel

LOG_2PI = float(np.log(2.0 * np.pi))
JITTERS = (0.0, 1e-10, 1e-8, 1e-6, 1e-4)  # relative to the mean diagonal


def factor(A: np.ndarray, what: str = "covariance") -> tuple[np.ndarray, float]:
    """Cholesky factor of a symmetric positive-definite matrix, computed in A's own memory.

    Returns (L, jitter added): ``L`` is Fortran-ordered and only its lower triangle is the
    factor (the strict upper triangle still holds A's entries; LAPACK's potrs/potri and
    ``solve_triangular(..., lower=True)`` never read it). No copy, no ``np.tril`` pass: this is
    the likelihood's hot path. A is overwritten. The jitter grows as in :func:`cholesky`.
    """
    N = len(A)
    if N == 0:
        return np.asfortranarray(A), 0.0
    c = A.T if A.flags.c_contiguous else np.asfortranarray(A)  # A symmetric: Aᵀ = A, F-ordered
    diag = np.diagonal(c).copy()
    scale = float(np.mean(diag))
    for rel in JITTERS:
        if rel:  # restore A's lower triangle from the untouched upper one, add jitter
            c = np.where(np.tri(N, k=-1, dtype=bool), c.T, c).T  # symmetric: .T is F-ordered
            c[np.diag_indices(N)] = diag + rel * scale
        L, info = lapack.dpotrf(c, lower=1, clean=0, overwrite_a=1)
        if info == 0 and np.all(np.isfinite(np.diagonal(L))):
            return L, rel * scale
        c = L
    raise NumericalError(
        f"Cholesky of the {what} ({N}×{N}) failed even with jitter "
        f"{JITTERS[-1]:g}×mean diagonal; the noise level is too small for the data or the inputs "
        "repeat: raise the noise floor (min_noise), remove duplicate samples or use fewer samples"
    )


def cholesky(A: np.ndarray, what: str = "covariance") -> tuple[np.ndarray, float]:
    """Lower Cholesky factor of a symmetric positive-definite matrix, with growing jitter.

    Returns (L, jitter added), L lower-triangular (zeros above the diagonal); A is not modified.
    Raises :class:`NumericalError` with a hint when even the largest jitter fails (as
    scikit-learn does for its failed Cholesky).
    """
    L, jitter = factor(np.array(A, dtype=float, order="F"), what)
    return np.tril(L), jitter


def symmetric_from_lower(C: np.ndarray) -> np.ndarray:
    """The full symmetric matrix whose lower triangle is C's (one pass, new array)."""
    return np.where(np.tri(len(C), dtype=bool), C, C.T)


@dataclass(frozen=True)
class Hyperparameters:
    """Log hyperparameters of the SGP (thesis §3.3.4: σ_w, σ_v, σ_z, ℓ).

    Attributes
    ----------
    log_sigma_w : float, log prior std of the (column-scaled) parameters W
    log_sigma_v : ndarray (n,), log noise std per output, y's unit
    theta : tuple of n ndarrays, each output's kernel log-parameters (empty when no kernel)
    """

    log_sigma_w: float
    log_sigma_v: np.ndarray
    theta: tuple

    def pack(self) -> np.ndarray:
        return np.concatenate([[self.log_sigma_w], self.log_sigma_v, *self.theta])

    @classmethod
    def unpack(cls, vec: np.ndarray, sizes) -> Hyperparameters:
        n = len(sizes)
        out, k = [], 1 + n
        for s in sizes:
            out.append(np.asarray(vec[k : k + s], float))
            k += s
        return cls(float(vec[0]), np.asarray(vec[1 : 1 + n], float), tuple(out))


# ----------------------------------------------------------------------------- per-output blocks
class ExactBlock:
    """``A = K_z + σ_v² I`` factorised exactly (Cholesky), one output.

    ``keep_kernel`` keeps ``K_z`` (attribute ``K``) for the likelihood gradient, so the kernel
    is evaluated once per likelihood call.
    """

    def __init__(
        self,
        kernel: Kernel | None,
        U: np.ndarray,
        theta: np.ndarray,
        noise_var: float,
        keep_kernel: bool = False,
    ):
        self.kernel, self.U, self.theta, self.noise_var = kernel, U, theta, noise_var
        N = len(U)
        self.K = None
        if kernel is None:
            self.L = None
            self._logdet = N * np.log(noise_var)
        else:
            K = kernel(U, U, theta)
            A = K.copy() if keep_kernel else K
            A[np.diag_indices(N)] += noise_var
            self.K = K if keep_kernel else None
            self.L, _ = factor(A, "SGP covariance K_z + σ_v² I")  # lower triangle only
            self._logdet = 2.0 * np.sum(np.log(np.diagonal(self.L)))

    def solve(self, B: np.ndarray) -> np.ndarray:
        if self.L is None:
            return B / self.noise_var
        x, _ = lapack.dpotrs(self.L, B, lower=1)
        return x

    def logdet(self) -> float:
        return self._logdet

    def inverse_lower(self, overwrite: bool = False) -> np.ndarray:
        """A⁻¹ in the lower triangle of an F-ordered array (LAPACK potri, no symmetrising);
        ``overwrite`` reuses the factor's memory (the block cannot solve afterwards)."""
        inv, info = lapack.dpotri(self.L, lower=1, overwrite_c=int(overwrite))
        if info != 0:
            raise NumericalError(f"inverting the SGP covariance failed (LAPACK potri info={info})")
        if overwrite:
            self.L = None
        return inv

    def inverse(self) -> np.ndarray:
        """A⁻¹ (N, N), symmetric."""
        return symmetric_from_lower(self.inverse_lower())

    def finalize(self, alpha: np.ndarray, F: np.ndarray) -> None:
        self.alpha, self.F = alpha, F

    def predict(self, Uq: np.ndarray):
        """(GP mean (Nq,), latent Z variance given W (Nq,), F_jᵀ A⁻¹ k_q as (Nq, m))."""
        Nq, m = len(Uq), self.F.shape[1]
        if self.kernel is None:
            return np.zeros(Nq), np.zeros(Nq), np.zeros((Nq, m))
        kq = self.kernel(Uq, self.U, self.theta)  # (Nq, N)
        v = solve_triangular(self.L, kq.T, lower=True, check_finite=False)
        Ainv_k = solve_triangular(self.L, v, lower=True, trans="T", check_finite=False)
        var = self.kernel.diag(Uq, self.theta) - np.sum(v * v, axis=0)
        return kq @ self.alpha, np.maximum(var, 0.0), Ainv_k.T @ self.F


class SparseBlock:
    """DTC/VFE inducing-point approximation ``A ≈ Q + σ_v² I``, ``Q = K_nm K_mm⁻¹ K_mn``.

    Solves with the Woodbury identity in O(N M²); predictive variance uses the exact prior
    variance k(q, q) (the DTC/VFE predictive, not the degenerate Q(q, q)).
    """

    def __init__(
        self,
        kernel: Kernel,
        U: np.ndarray,
        theta: np.ndarray,
        noise_var: float,
        inducing: np.ndarray,
    ):
        self.kernel, self.U, self.theta, self.noise_var, self.Z = (
            kernel,
            U,
            theta,
            noise_var,
            inducing,
        )
        Kmm = kernel(inducing, inducing, theta)
        self.Lmm, _ = cholesky(Kmm, "inducing-point covariance K_mm")
        self.Knm = kernel(U, inducing, theta)
        S = Kmm + self.Knm.T @ self.Knm / noise_var
        self.Ls, _ = cholesky(S, "inducing-point system K_mm + K_mn K_nm / σ_v²")
        N = len(U)
        # log|Q + σ²I| = N log σ² + log|I + VᵀV/σ²| V = K_nm L_mm⁻ᵀ (stable; GPflow SGPR)
        V = solve_triangular(self.Lmm, self.Knm.T, lower=True, check_finite=False)
        LB, _ = cholesky(np.eye(len(inducing)) + V @ V.T / noise_var, "I + VᵀV/σ_v²")
        self._logdet = 2.0 * np.sum(np.log(np.diag(LB))) + N * np.log(noise_var)

    def solve(self, B: np.ndarray) -> np.ndarray:
        s2 = self.noise_var
        inner = cho_solve((self.Ls, True), self.Knm.T @ B, check_finite=False)
        return B / s2 - self.Knm @ inner / (s2 * s2)

    def logdet(self) -> float:
        return self._logdet

    def finalize(self, alpha: np.ndarray, F: np.ndarray) -> None:
        self.gamma = cho_solve((self.Lmm, True), self.Knm.T @ alpha, check_finite=False)  # K_mm⁻¹ K_mn α
        self.H = cho_solve((self.Ls, True), self.Knm.T @ F, check_finite=False) / self.noise_var  # S⁻¹ K_mn F / σ²

    def predict(self, Uq: np.ndarray):
        Kqm = self.kernel(Uq, self.Z, self.theta)
        a = solve_triangular(self.Lmm, Kqm.T, lower=True, check_finite=False)
        b = solve_triangular(self.Ls, Kqm.T, lower=True, check_finite=False)
        var = self.kernel.diag(Uq, self.theta) - np.sum(a * a, 0) + np.sum(b * b, 0)
        return Kqm @ self.gamma, np.maximum(var, 0.0), Kqm @ self.H


# ----------------------------------------------------------------------------- shared W
@dataclass
class Posterior:
    """Fitted posterior: blocks per output, W's posterior (scaled coordinates) and noise."""

    blocks: list
    w_mean: np.ndarray  # (m,) ŵ
    M_chol: np.ndarray | None  # (m, m) Cholesky of M = cov(W | y)⁻¹
    noise_var: np.ndarray  # (n,)
    log_likelihood: float

    @property
    def w_cov(self) -> np.ndarray:
        m = self.w_mean.size
        if m == 0:
            return np.zeros((0, 0))
        return cho_solve((self.M_chol, True), np.eye(m))

    def predict(self, Uq: np.ndarray, Fq: np.ndarray):
        """Posterior at queries. Uq (Nq, p) scaled inputs, Fq (Nq, n, m) scaled features.

        Returns mean (Nq, n), latent variance (Nq, n) (eq. 3.20), parametric part f ŵ (Nq, n).
        """
        Nq, n = len(Uq), len(self.blocks)
        mean, var, par = np.zeros((Nq, n)), np.zeros((Nq, n)), np.zeros((Nq, n))
        for j, blk in enumerate(self.blocks):
            gp_mean, gp_var, FtAk = blk.predict(Uq)
            par[:, j] = Fq[:, j] @ self.w_mean
            mean[:, j] = par[:, j] + gp_mean
            var[:, j] = gp_var
            if self.w_mean.size:
                r = Fq[:, j] - FtAk  # R&W eq. (2.42): W's uncertainty seen through f - Fᵀ A⁻¹ k
                s = solve_triangular(self.M_chol, r.T, lower=True, check_finite=False)
                var[:, j] += np.sum(s * s, axis=0)
        return mean, var, par


def _shared_w(blocks, Y, F, sigma_w2):
    """Solve the shared-W system. Returns a_j, G_j lists, B, b, M Cholesky, ŵ, α (N, n)."""
    N, n = Y.shape
    m = F.shape[2]
    a, G = [], []
    for j, blk in enumerate(blocks):  # one solve per block for [y_j, F_j]
        S = blk.solve(np.column_stack([Y[:, j], F[:, j]]))
        a.append(S[:, 0])
        G.append(S[:, 1:])
    B = sum(F[:, j].T @ G[j] for j in range(n)) if m else np.zeros((0, 0))
    b = sum(F[:, j].T @ a[j] for j in range(n)) if m else np.zeros(0)
    if m:
        Mmat = B + np.eye(m) / sigma_w2
        LM, _ = cholesky(Mmat, "parameter precision Σ_w⁻¹ + Fᵀ A⁻¹ F")
        w = cho_solve((LM, True), b, check_finite=False)
    else:
        LM, w = None, np.zeros(0)
    alpha = np.column_stack([a[j] - G[j] @ w for j in range(n)])
    return a, G, B, b, LM, w, alpha


def fit_posterior(kernels, U, Y, F, hp: Hyperparameters, inducing: np.ndarray | None = None) -> Posterior:
    """Posterior for fixed hyperparameters; ``inducing`` (M, p) switches GP blocks to DTC/VFE."""
    N, n = Y.shape
    noise = np.exp(2.0 * hp.log_sigma_v)
    blocks = []
    for j in range(n):
        if kernels[j] is not None and inducing is not None:
            blocks.append(SparseBlock(kernels[j], U, hp.theta[j], noise[j], inducing))
        else:
            blocks.append(ExactBlock(kernels[j], U, hp.theta[j], noise[j]))
    sw2 = np.exp(2.0 * hp.log_sigma_w)
    _, _, _, _, LM, w, alpha = _shared_w(blocks, Y, F, sw2)
    for j, blk in enumerate(blocks):
        blk.finalize(alpha[:, j], F[:, j])
    m = F.shape[2]
    logdet = sum(blk.logdet() for blk in blocks)
    if m:
        logdet += m * np.log(sw2) + 2.0 * np.sum(np.log(np.diag(LM)))
    ll = -0.5 * float(np.sum(Y * alpha)) - 0.5 * logdet - 0.5 * N * n * LOG_2PI
    return Posterior(blocks, w, LM, noise, float(ll))


def negative_log_likelihood(vec: np.ndarray, kernels, U, Y, F, sizes, grad: bool = True):
    """−log p(y | hyperparameters) and its gradient w.r.t. the packed log-hyperparameters.

    Gradient: ``∂(−log p)/∂θ = −½ tr(W_j ∂A_j/∂θ)`` with ``W = α αᵀ − K⁻¹`` (R&W eq. 5.9),
    evaluated block by block: ``(K⁻¹)_jj = A_j⁻¹ − G_j M⁻¹ G_jᵀ`` with ``G_j = A_j⁻¹ F_j``, so
    ``W_j = V Vᵀ − A_j⁻¹`` with ``V = [α_j, G_j L_M⁻ᵀ]`` (one potri and one syrk per block);
    the kernel contracts W_j with all its parameter derivatives at once
    (:meth:`Kernel.weighted_gradient`). For σ_w, ``∂K/∂log σ_w = 2 σ_w² F Fᵀ`` gives
    ``−σ_w² (|Fᵀα|² − tr(Fᵀ K⁻¹ F))``, ``Fᵀ K⁻¹ F = B − B M⁻¹ B``.
    Cost per output: one Cholesky and one potri of N×N (N³ flops) plus O(N² (m + p)).
    """
    hp = Hyperparameters.unpack(vec, sizes)
    N, n = Y.shape
    m = F.shape[2]
    noise = np.exp(2.0 * hp.log_sigma_v)
    blocks = [ExactBlock(kernels[j], U, hp.theta[j], noise[j], keep_kernel=grad) for j in range(n)]
    sw2 = np.exp(2.0 * hp.log_sigma_w)
    a, G, B, b, LM, w, alpha = _shared_w(blocks, Y, F, sw2)
    logdet = sum(blk.logdet() for blk in blocks)
    if m:
        logdet += m * np.log(sw2) + 2.0 * np.sum(np.log(np.diag(LM)))
    nll = 0.5 * float(np.sum(Y * alpha)) + 0.5 * logdet + 0.5 * N * n * LOG_2PI
    if not grad:
        return nll
    g = np.zeros_like(vec)
    if m:
        Ftalpha = sum(F[:, j].T @ alpha[:, j] for j in range(n))
        MinvB = cho_solve((LM, True), B, check_finite=False)
        tr_FKF = np.trace(B) - np.sum(B * MinvB.T)
        g[0] = -sw2 * (Ftalpha @ Ftalpha - tr_FKF)
    k = 1 + n
    for j in range(n):
        blk, al = blocks[j], alpha[:, j]
        blocks[j] = None  # free each block's N×N arrays once its gradient is done
        # G M⁻¹ Gᵀ = H Hᵀ, H = G L_M⁻ᵀ
        H = solve_triangular(LM, G[j].T, lower=True, check_finite=False).T if m else G[j]
        if blk.L is None:  # A = σ² I
            tr_Kinv = N / noise[j] - np.sum(H * H)
            g[1 + j] = -noise[j] * (al @ al - tr_Kinv)
            continue
        V = np.asfortranarray(np.column_stack([al, H]))
        # lower triangle of W = V Vᵀ − A⁻¹, in the factor's memory
        Wl = blas.dsyrk(1.0, V, beta=-1.0, c=blk.inverse_lower(overwrite=True), lower=1, overwrite_c=1)
        g[1 + j] = -noise[j] * np.trace(Wl)  # ∂A/∂log σ_v = 2σ_v² I
        Wm = symmetric_from_lower(Wl)
        del Wl
        g[k : k + sizes[j]] = -0.5 * blk.kernel.weighted_gradient(U, U, hp.theta[j], Wm, blk.K)
        k += sizes[j]
    return nll, g
