"""Per-output covariance blocks of the SGP (thesis §3.3.1): ``A_j = K_z,j + σ_v,j² I`` exactly
(:class:`ExactBlock`, a Cholesky factor) or by inducing points (:class:`SparseBlock`, Titsias's
DTC/VFE, O(N M²)), and the factorisations they share. :mod:`diegocal.sgp.gp` assembles them with
the shared parametric part W.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import blas, lapack, solve_triangular

from diegocal.errors import NumericalError
from diegocal.sgp.kernels import Kernel

LOG_2PI = float(np.log(2.0 * np.pi))
JITTERS = (0.0, 1e-10, 1e-8, 1e-6, 1e-4)  # relative to the mean diagonal
QUERY_CHUNK = 2000  # queries predicted at once (memory O(QUERY_CHUNK · N) per output)


def input_scaling(U: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(mean, std) per input column by which an estimator fitted on ``U`` standardises its
    inputs (a constant column keeps std 1)."""
    std = U.std(0)
    return U.mean(0), np.where(std > 0, std, 1.0)


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
        if kernel is None:  # no GP: only the row count is needed (the inputs would live as long as the fit)
            self.U = U[:0].copy()
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

    def penalty(self) -> float:
        return 0.0

    def nll_gradient(self, alpha: np.ndarray, H: np.ndarray) -> tuple[float, np.ndarray]:
        """∂(−log p)/∂(log σ_v, kernel θ) of this block: ``−½ tr(W ∂A)`` with
        ``W = V Vᵀ − A⁻¹``, ``V = [α, H]`` (one potri and one syrk; the factor's memory is
        reused, so the block cannot solve afterwards)."""
        s2 = self.noise_var
        if self.L is None:  # A = σ² I
            return -s2 * (alpha @ alpha + np.sum(H * H) - len(alpha) / s2), np.zeros(0)
        V = np.asfortranarray(np.column_stack([alpha, H]))
        Wl = blas.dsyrk(1.0, V, beta=-1.0, c=self.inverse_lower(overwrite=True), lower=1, overwrite_c=1)
        g_noise = -s2 * np.trace(Wl)  # ∂A/∂log σ_v = 2σ_v² I
        Wm = symmetric_from_lower(Wl)
        del Wl
        return g_noise, -0.5 * self.kernel.weighted_gradient(self.U, self.U, self.theta, Wm, self.K)

    def finalize(self, alpha: np.ndarray, F: np.ndarray) -> None:
        """Keep what :meth:`predict` needs: α and, with a kernel, F_j (N, m) for F_jᵀ A⁻¹ k_q.
        Without one only F_j's column count is kept (an empty (0, m) array): F_j is a view of
        the whole scaled training regressor, which would otherwise live as long as the fit."""
        self.alpha = alpha
        self.F = F if self.kernel is not None else np.empty((0, F.shape[1]))

    def predict(self, Uq: np.ndarray, variance: bool = True):
        """(GP mean (Nq,), latent Z variance given W (Nq,), F_jᵀ A⁻¹ k_q as (Nq, m)); without
        ``variance`` the last two are None (the mean alone costs O(Nq N), not O(Nq N²))."""
        Nq, m = len(Uq), self.F.shape[1]
        if self.kernel is None:
            return (np.zeros(Nq), np.zeros(Nq), np.zeros((Nq, m))) if variance else (np.zeros(Nq), None, None)
        kq = self.kernel(Uq, self.U, self.theta)  # (Nq, N)
        if not variance:
            return kq @ self.alpha, None, None
        v = solve_triangular(self.L, kq.T, lower=True, check_finite=False)
        Ainv_k = solve_triangular(self.L, v, lower=True, trans="T", check_finite=False)
        var = self.kernel.diag(Uq, self.theta) - np.sum(v * v, axis=0)
        return kq @ self.alpha, np.maximum(var, 0.0), Ainv_k.T @ self.F


class SparseBlock:
    """Inducing-point approximation ``A ≈ Q + σ_v² I``, ``Q = K_nm K_mm⁻¹ K_mn`` (DTC/VFE).

    In the stable form of GPflow's SGPR: ``V = L_mm⁻¹ K_mn`` (M, N), ``Q = Vᵀ V``,
    ``B = I + V Vᵀ/σ_v²``, so ``A⁻¹ = I/σ² − Vᵀ B⁻¹ V/σ⁴`` and ``log|A| = N log σ² + log|B|``:
    O(N M²). The likelihood is Titsias's collapsed variational (VFE) bound, the Gaussian one
    minus ``tr(K_nn − Q)/(2σ_v²)`` (:meth:`penalty`); the predictive variance uses the exact
    prior variance k(q, q) (the DTC/VFE predictive, not the degenerate Q(q, q)).
    """

    def __init__(
        self,
        kernel: Kernel,
        U: np.ndarray,
        theta: np.ndarray,
        noise_var: float,
        inducing: np.ndarray,
        keep_kernel: bool = False,
    ):
        self.kernel, self.U, self.theta, self.noise_var, self.Z = kernel, U, theta, noise_var, inducing
        Kmm = kernel(inducing, inducing, theta)
        self.Kmm = Kmm.copy() if keep_kernel else None
        self.Lmm, _ = factor(Kmm, "inducing-point covariance K_mm")
        Kmn = kernel(inducing, U, theta)  # (M, N)
        self.Kmn = Kmn if keep_kernel else None
        self.V = solve_triangular(self.Lmm, Kmn, lower=True, check_finite=False)
        self.VVt = self.V @ self.V.T
        Bm = self.VVt / noise_var
        Bm[np.diag_indices(len(Bm))] += 1.0
        self.LB, _ = factor(Bm, "inducing-point system I + V Vᵀ/σ_v²")
        self._logdet = 2.0 * np.sum(np.log(np.diagonal(self.LB))) + len(U) * np.log(noise_var)
        # tr(K_nn − Q) ≥ 0: how much prior variance the inducing inputs miss
        self.trace_gap = max(float(np.sum(kernel.diag(U, theta)) - np.sum(self.V * self.V)), 0.0)

    @property
    def gap(self) -> float:
        """Mean prior variance per sample that the inducing inputs miss, in units of σ_v²
        (:mod:`diegocal.sgp.inducing`)."""
        return self.trace_gap / (len(self.U) * self.noise_var)

    def _Binv(self, X):
        x, _ = lapack.dpotrs(self.LB, X, lower=1)
        return x

    def solve(self, B: np.ndarray) -> np.ndarray:
        s2 = self.noise_var
        return B / s2 - self.V.T @ self._Binv(self.V @ B) / (s2 * s2)

    def logdet(self) -> float:
        return self._logdet

    def penalty(self) -> float:
        """VFE's ``tr(K_nn − Q)/(2σ_v²)``, subtracted from the log likelihood."""
        return self.trace_gap / (2.0 * self.noise_var)

    def finalize(self, alpha: np.ndarray, F: np.ndarray) -> None:
        s2 = self.noise_var
        # K_mm⁻¹ K_mn α = L_mm⁻ᵀ V α; S⁻¹ K_mn F / σ² = L_mm⁻ᵀ B⁻¹ V F / σ² (S = L_mm B L_mmᵀ)
        self.gamma = solve_triangular(self.Lmm, self.V @ alpha, lower=True, trans="T", check_finite=False)
        self.H = solve_triangular(self.Lmm, self._Binv(self.V @ F), lower=True, trans="T", check_finite=False) / s2

    def predict(self, Uq: np.ndarray, variance: bool = True):
        Kqm = self.kernel(Uq, self.Z, self.theta)
        if not variance:
            return Kqm @ self.gamma, None, None
        a = solve_triangular(self.Lmm, Kqm.T, lower=True, check_finite=False)
        b = solve_triangular(self.LB, a, lower=True, check_finite=False)  # S = L_mm B L_mmᵀ
        var = self.kernel.diag(Uq, self.theta) - np.sum(a * a, 0) + np.sum(b * b, 0)
        return Kqm @ self.gamma, np.maximum(var, 0.0), Kqm @ self.H

    def nll_gradient(self, alpha: np.ndarray, H: np.ndarray) -> tuple[float, np.ndarray]:
        """∂(−VFE bound)/∂(log σ_v, kernel θ) of this block, never forming N×N.

        With ``W = α αᵀ − (K⁻¹)_jj`` (``(K⁻¹)_jj = A⁻¹ − H Hᵀ``), ``W' = W + I/σ²`` and
        ``R = K_mm⁻¹ K_mn``: ``∂Q = ∂K_nm R + Rᵀ ∂K_mn − Rᵀ ∂K_mm R`` gives
        ``−½ tr(W' ∂Q) = −⟨W' Rᵀ, ∂K_nm⟩ + ½⟨R W' Rᵀ, ∂K_mm⟩``, plus ``∂ tr K_nn/(2σ²)``;
        in ``W' Rᵀ = α (Rα)ᵀ + H (RH)ᵀ + Vᵀ B⁻¹ V Rᵀ/σ⁴`` the ``I/σ²`` of A⁻¹ and of W' cancel.
        """
        s2, N, M = self.noise_var, len(self.U), len(self.Z)
        LBinv = solve_triangular(self.LB, np.eye(M), lower=True, check_finite=False)
        tr_Ainv = (N - M + np.sum(LBinv * LBinv)) / s2  # A⁻¹ = I/σ² − Vᵀ B⁻¹ V/σ⁴
        trW = alpha @ alpha + np.sum(H * H) - tr_Ainv
        g_noise = -s2 * trW - self.trace_gap / s2
        Rt = np.column_stack([alpha, H])  # [α, H] and R [α, H] (M, 1 + m)
        RX = solve_triangular(self.Lmm, self.V @ Rt, lower=True, trans="T", check_finite=False)
        RVt = solve_triangular(self.Lmm, self.VVt, lower=True, trans="T", check_finite=False)  # R Vᵀ
        C = self._Binv(RVt.T) / (s2 * s2)  # B⁻¹ V Rᵀ/σ⁴ (M, M)
        Et = RX @ Rt.T + C.T @ self.V  # (W' Rᵀ)ᵀ (M, N)
        RWR = RX @ RX.T + RVt @ C  # R W' Rᵀ (M, M)
        k = self.kernel
        g_theta = (
            -k.weighted_gradient(self.Z, self.U, self.theta, Et, self.Kmn)
            + 0.5 * k.weighted_gradient(self.Z, self.Z, self.theta, RWR, self.Kmm)
            + k.weighted_diag_gradient(self.U, self.theta, np.full(N, 0.5 / s2))
        )
        return g_noise, g_theta
