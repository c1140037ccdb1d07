"""Covariance kernels for the non-parametric part Z of the SGP (thesis eq. 3.4, 3.21).

Small objects in the style of tinygp (STYLE.md): a kernel evaluates a pair of input sets,
composes with ``+`` and ``*``, and :class:`Subspace` makes one act on a subset of the inputs.
Hyperparameters live outside the kernel, as a float vector ``theta`` of *log* values (the
optimiser's door); :meth:`Kernel.gradients` yields ``∂K/∂theta_p`` one matrix at a time so the
marginal-likelihood gradient needs only O(N²) extra memory.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np


class Kernel:
    """Base class: ``k(X1, X2, theta) -> (N1, N2)`` with ``theta`` the kernel's log-parameters."""

    names: tuple[str, ...] = ()

    @property
    def n_params(self) -> int:
        return len(self.names)

    def __call__(self, X1: np.ndarray, X2: np.ndarray, theta: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def diag(self, X: np.ndarray, theta: np.ndarray) -> np.ndarray:
        """``k(x, x)`` for each row: shape (N,)."""
        return np.array([self(x[None], x[None], theta)[0, 0] for x in X])

    def gradients(self, X: np.ndarray, theta: np.ndarray) -> Iterator[np.ndarray]:
        """Yield ``∂K(X, X)/∂theta_p`` (N, N) for p = 0 .. n_params-1."""
        raise NotImplementedError

    def __add__(self, other: Kernel) -> Kernel:
        return Sum(self, other)

    def __mul__(self, other: Kernel) -> Kernel:
        return Product(self, other)


class SquaredExponential(Kernel):
    """ARD squared-exponential kernel, thesis eq. (3.4) for one output.

    .. math:: k(u, \\tilde u) = \\sigma_z^2 \\exp(-(u-\\tilde u)^T P^{-1} (u-\\tilde u)/2),
              \\quad P = \\mathrm{diag}(\\ell_1^2, \\dots, \\ell_p^2)

    ``theta = [log σ_z, log ℓ_1, ..., log ℓ_p]``. The thesis writes σ_z for the signal
    *variance*; here σ_z is its square root (same model, a standard deviation in y's unit).

    Parameters
    ----------
    n_dims : int, p, the number of input dimensions the kernel sees
    """

    def __init__(self, n_dims: int):
        self.n_dims = int(n_dims)
        self.names = ("log_sigma_z",) + tuple(f"log_ell_{d}" for d in range(self.n_dims))

    def _scaled(self, X, theta):
        return np.asarray(X, float) / np.exp(theta[1:])

    def __call__(self, X1, X2, theta):
        A, B = self._scaled(X1, theta), self._scaled(X2, theta)
        d2 = (A * A).sum(1)[:, None] + (B * B).sum(1)[None, :] - 2.0 * A @ B.T
        return np.exp(2.0 * theta[0]) * np.exp(-0.5 * np.maximum(d2, 0.0))

    def diag(self, X, theta):
        return np.full(len(X), np.exp(2.0 * theta[0]))

    def gradients(self, X, theta):
        K = self(X, X, theta)
        yield 2.0 * K  # ∂/∂ log σ_z
        A = self._scaled(X, theta)
        for d in range(self.n_dims):
            diff = A[:, d][:, None] - A[:, d][None, :]
            yield K * diff * diff  # ∂/∂ log ℓ_d


class Constant(Kernel):
    """``k = c²`` everywhere; ``theta = [log c]``."""

    names = ("log_c",)

    def __call__(self, X1, X2, theta):
        return np.full((len(X1), len(X2)), np.exp(2.0 * theta[0]))

    def diag(self, X, theta):
        return np.full(len(X), np.exp(2.0 * theta[0]))

    def gradients(self, X, theta):
        yield np.full((len(X), len(X)), 2.0 * np.exp(2.0 * theta[0]))


class Subspace(Kernel):
    """A kernel acting on the input columns ``dims`` only (tinygp ``transforms.Subspace``)."""

    def __init__(self, dims, kernel: Kernel):
        self.dims = np.asarray(dims, dtype=int)
        self.kernel = kernel
        self.names = kernel.names

    def __call__(self, X1, X2, theta):
        return self.kernel(np.asarray(X1)[:, self.dims], np.asarray(X2)[:, self.dims], theta)

    def diag(self, X, theta):
        return self.kernel.diag(np.asarray(X)[:, self.dims], theta)

    def gradients(self, X, theta):
        yield from self.kernel.gradients(np.asarray(X)[:, self.dims], theta)


class Sum(Kernel):
    """``k1 + k2``; ``theta = [theta1, theta2]``."""

    def __init__(self, k1: Kernel, k2: Kernel):
        self.k1, self.k2 = k1, k2
        self.names = tuple(f"k1.{n}" for n in k1.names) + tuple(f"k2.{n}" for n in k2.names)

    def _split(self, theta):
        return theta[: self.k1.n_params], theta[self.k1.n_params :]

    def __call__(self, X1, X2, theta):
        t1, t2 = self._split(theta)
        return self.k1(X1, X2, t1) + self.k2(X1, X2, t2)

    def diag(self, X, theta):
        t1, t2 = self._split(theta)
        return self.k1.diag(X, t1) + self.k2.diag(X, t2)

    def gradients(self, X, theta):
        t1, t2 = self._split(theta)
        yield from self.k1.gradients(X, t1)
        yield from self.k2.gradients(X, t2)


class Product(Sum):
    """``k1 * k2`` (elementwise); ``theta = [theta1, theta2]``."""

    def __call__(self, X1, X2, theta):
        t1, t2 = self._split(theta)
        return self.k1(X1, X2, t1) * self.k2(X1, X2, t2)

    def diag(self, X, theta):
        t1, t2 = self._split(theta)
        return self.k1.diag(X, t1) * self.k2.diag(X, t2)

    def gradients(self, X, theta):
        t1, t2 = self._split(theta)
        K1, K2 = self.k1(X, X, t1), self.k2(X, X, t2)
        for g in self.k1.gradients(X, t1):
            yield g * K2
        for g in self.k2.gradients(X, t2):
            yield K1 * g


def is_lengthscale(name: str) -> bool:
    """True for a log length-scale parameter name (used by priors and bounds)."""
    return name.rsplit(".", 1)[-1].startswith("log_ell")


def is_amplitude(name: str) -> bool:
    """True for a log signal standard deviation (σ_z) parameter name."""
    return name.rsplit(".", 1)[-1] == "log_sigma_z"
