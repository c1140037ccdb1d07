"""Covariance kernels for the non-parametric part Z of the SGP (thesis eq. 3.4, 3.21).

Small objects in the style of tinygp (STYLE.md): a kernel evaluates a pair of input sets,
composes with ``+`` and ``*``, and :class:`Subspace` makes one act on a subset of the inputs.
Hyperparameters live outside the kernel, as a float vector ``theta`` of *log* values (the
optimiser's door); :meth:`Kernel.gradients` yields ``∂K/∂theta_p`` one matrix at a time so the
marginal-likelihood gradient needs only O(N²) extra memory. The likelihood itself uses
:meth:`Kernel.weighted_gradient`, the contraction ``Σ_ab W_ab ∂K_ab/∂theta_p`` for all ``p`` at
once, which the squared-exponential kernel evaluates with one matrix product and no per-parameter
N×N matrix.
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

    @property
    def lengthscale_inputs(self) -> tuple[int | None, ...]:
        """Per log-parameter, the input column whose length-scale it is (None for the others)."""
        return (None,) * self.n_params

    def __call__(self, X1: np.ndarray, X2: np.ndarray, theta: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def diag(self, X: np.ndarray, theta: np.ndarray) -> np.ndarray:
        """``k(x, x)`` for each row: shape (N,)."""
        return np.array([self(x[None], x[None], theta)[0, 0] for x in X])

    def gradients(self, X: np.ndarray, theta: np.ndarray) -> Iterator[np.ndarray]:
        """Yield ``∂K(X, X)/∂theta_p`` (N, N) for p = 0 .. n_params-1."""
        raise NotImplementedError

    def weighted_gradient(self, X1, X2, theta, W, K=None) -> np.ndarray:
        """``Σ_ab W_ab ∂k(X1, X2)_ab/∂theta_p`` for every p: shape (n_params,).

        W (N1, N2) is the weight (the likelihood's ``α αᵀ − K⁻¹``); K (N1, N2), when given,
        is ``k(X1, X2, theta)`` already evaluated (saves a kernel evaluation). This default
        contracts the dense :meth:`gradients`, so it serves only ``X1 is X2``; kernels
        override it with a closed form that also serves cross-covariances (sparse inference).
        """
        if X1 is not X2:
            raise NotImplementedError(f"{type(self).__name__} has no cross-covariance gradient")
        return np.array([np.sum(W * dK) for dK in self.gradients(X1, theta)])

    def weighted_diag_gradient(self, X, theta, w) -> np.ndarray:
        """``Σ_a w_a ∂k(x_a, x_a)/∂theta_p`` for every p: shape (n_params,); w (N,)."""
        out = np.zeros(self.n_params)
        for x, wa in zip(np.asarray(X), w, strict=True):
            out += wa * np.array([dK[0, 0] for dK in self.gradients(x[None], theta)])
        return out

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

    @property
    def lengthscale_inputs(self):
        return (None, *range(self.n_dims))

    def _scaled(self, X, theta):
        return np.asarray(X, float) / np.exp(theta[1:])

    def __call__(self, X1, X2, theta):
        A = self._scaled(X1, theta)
        B = A if X2 is X1 else self._scaled(X2, theta)
        # log k = log σ_z² - |a - b|²/2 = a·b + (log σ_z² - |a|²/2) - |b|²/2, in place
        G = A @ B.T
        G += (2.0 * theta[0] - 0.5 * np.einsum("ij,ij->i", A, A))[:, None]
        G -= 0.5 * np.einsum("ij,ij->i", B, B)[None, :]
        np.minimum(G, 2.0 * theta[0], out=G)  # |a - b|² ≥ 0 despite rounding
        return np.exp(G, out=G)

    def diag(self, X, theta):
        return np.full(len(X), np.exp(2.0 * theta[0]))

    def gradients(self, X, theta):
        K = self(X, X, theta)
        yield 2.0 * K  # ∂/∂ log σ_z
        A = self._scaled(X, theta)
        for d in range(self.n_dims):
            diff = A[:, d][:, None] - A[:, d][None, :]
            yield K * diff * diff  # ∂/∂ log ℓ_d

    def weighted_gradient(self, X1, X2, theta, W, K=None):
        """Closed form: with ``P = W ∘ K`` and scaled inputs ``a = x/ℓ``,
        ``∂K_ab/∂log ℓ_d = K_ab (a_d - b_d)²`` gives
        ``Σ_ab P_ab (a_d - b_d)² = Σ_a r_a a_d² + Σ_b c_b b_d² - 2 Σ_a a_d (P b_d)_a``
        (r, c the row and column sums of P): one (N1, N2) × (N2, p+1) product for all d."""
        if K is None:
            K = self(X1, X2, theta)
        A = self._scaled(X1, theta)
        B = A if X2 is X1 else self._scaled(X2, theta)
        P = W * K
        PB = P @ np.hstack([B, np.ones((len(B), 1))])  # [P b_1 .. P b_p, r]
        r, c = PB[:, -1], P.sum(axis=0)
        out = np.empty(1 + self.n_dims)
        out[0] = 2.0 * np.sum(r)  # ∂K/∂log σ_z = 2K
        out[1:] = r @ (A * A) + c @ (B * B) - 2.0 * np.sum(A * PB[:, :-1], axis=0)
        return out

    def weighted_diag_gradient(self, X, theta, w):
        out = np.zeros(1 + self.n_dims)
        out[0] = 2.0 * np.exp(2.0 * theta[0]) * np.sum(w)  # k(x, x) = σ_z²
        return out


class Constant(Kernel):
    """``k = c²`` everywhere; ``theta = [log c]``."""

    names = ("log_c",)

    def __call__(self, X1, X2, theta):
        return np.full((len(X1), len(X2)), np.exp(2.0 * theta[0]))

    def diag(self, X, theta):
        return np.full(len(X), np.exp(2.0 * theta[0]))

    def gradients(self, X, theta):
        yield np.full((len(X), len(X)), 2.0 * np.exp(2.0 * theta[0]))

    def weighted_gradient(self, X1, X2, theta, W, K=None):
        return np.array([2.0 * np.exp(2.0 * theta[0]) * np.sum(W)])

    def weighted_diag_gradient(self, X, theta, w):
        return np.array([2.0 * np.exp(2.0 * theta[0]) * np.sum(w)])


class Subspace(Kernel):
    """A kernel acting on the input columns ``dims`` only (tinygp ``transforms.Subspace``)."""

    def __init__(self, dims, kernel: Kernel):
        self.dims = np.asarray(dims, dtype=int)
        self.kernel = kernel
        self.names = kernel.names

    @property
    def lengthscale_inputs(self):
        return tuple(None if d is None else int(self.dims[d]) for d in self.kernel.lengthscale_inputs)

    def _select(self, X1, X2):
        S1 = np.asarray(X1)[:, self.dims]
        return S1, (S1 if X2 is X1 else np.asarray(X2)[:, self.dims])  # keep k(X, X) symmetric

    def __call__(self, X1, X2, theta):
        return self.kernel(*self._select(X1, X2), theta)

    def diag(self, X, theta):
        return self.kernel.diag(np.asarray(X)[:, self.dims], theta)

    def gradients(self, X, theta):
        yield from self.kernel.gradients(np.asarray(X)[:, self.dims], theta)

    def weighted_gradient(self, X1, X2, theta, W, K=None):
        return self.kernel.weighted_gradient(*self._select(X1, X2), theta, W, K)

    def weighted_diag_gradient(self, X, theta, w):
        return self.kernel.weighted_diag_gradient(np.asarray(X)[:, self.dims], theta, w)


class Sum(Kernel):
    """``k1 + k2``; ``theta = [theta1, theta2]``."""

    def __init__(self, k1: Kernel, k2: Kernel):
        self.k1, self.k2 = k1, k2
        self.names = tuple(f"k1.{n}" for n in k1.names) + tuple(f"k2.{n}" for n in k2.names)

    @property
    def lengthscale_inputs(self):
        return self.k1.lengthscale_inputs + self.k2.lengthscale_inputs

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

    def weighted_gradient(self, X1, X2, theta, W, K=None):
        t1, t2 = self._split(theta)
        return np.concatenate([self.k1.weighted_gradient(X1, X2, t1, W), self.k2.weighted_gradient(X1, X2, t2, W)])

    def weighted_diag_gradient(self, X, theta, w):
        t1, t2 = self._split(theta)
        return np.concatenate([self.k1.weighted_diag_gradient(X, t1, w), self.k2.weighted_diag_gradient(X, t2, w)])


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

    def weighted_gradient(self, X1, X2, theta, W, K=None):
        # ∂(K1 ∘ K2) = ∂K1 ∘ K2 + K1 ∘ ∂K2: each factor sees the weight W ∘ (the other factor)
        t1, t2 = self._split(theta)
        K1, K2 = self.k1(X1, X2, t1), self.k2(X1, X2, t2)
        return np.concatenate(
            [
                self.k1.weighted_gradient(X1, X2, t1, W * K2, K1),
                self.k2.weighted_gradient(X1, X2, t2, W * K1, K2),
            ]
        )

    def weighted_diag_gradient(self, X, theta, w):
        t1, t2 = self._split(theta)
        d1, d2 = self.k1.diag(X, t1), self.k2.diag(X, t2)
        return np.concatenate(
            [
                self.k1.weighted_diag_gradient(X, t1, w * d2),
                self.k2.weighted_diag_gradient(X, t2, w * d1),
            ]
        )


class Region(Kernel):
    """A kernel cut in two at an onset along input ``dim``: ``k_0`` within each side, nothing
    across, the side above the onset scaled by a ratio r (the changepoint kernel of Garnett et al.
    2010 and Lloyd et al. 2014, both sides of one base kernel):

    .. math:: k(x, x') = [b(x) b(x') + r^2 a(x) a(x')] \\, k_0(x, x'), \\quad
              a = \\mathrm{sigmoid}((x_{dim} - c)/w), \\; b = 1 - a

    Why: a friction confined to part of a joint's range (a cable, a hose, a hard stop) is a step
    in that joint's angle, and an SE kernel carries a step some length-scales to each side of it,
    where the residual has none (issue #14: the 3-link arm's joint 3, onset 1.78 rad, an SE GP on
    PR's residual had twice PR's error just below the onset and covered 0.05 of it within ±2σ).
    Cut at the onset, each side is its own GP of the same length-scales.

    ``theta = [c, log w, log r, theta_0]``, c and w in the units of input ``dim`` (standardised);
    ``c = REGION_OFF`` puts every input below it: the kernel is then ``k_0``. ML-II holds c and w
    (:func:`is_fixed`): the likelihood is flat in c between two samples and the step must sit
    between the right two (3-link arm, issue #14: an onset 0.01 rad below the friction's doubled
    the held-out error), so :meth:`~diegocal.sgp.region.RegionScan._region_scan` places it by
    a search over the samples; their gradients serve tests and other uses.
    """

    def __init__(self, dim: int, kernel: Kernel):
        self.dim = int(dim)
        self.kernel = kernel
        self.names = ("region_onset", "log_region_width", "log_region_ratio") + tuple(
            f"inner.{n}" for n in kernel.names
        )

    @property
    def lengthscale_inputs(self):
        return (None, None, None, *self.kernel.lengthscale_inputs)

    def _above(self, X, theta) -> tuple[np.ndarray, np.ndarray]:
        """(a, ∂a/∂c) per row; ∂a/∂log w = ∂a/∂c · (x - c)."""
        z = (np.asarray(X)[:, self.dim] - theta[0]) / np.exp(theta[1])
        a = 0.5 * (1.0 + np.tanh(0.5 * z))  # sigmoid(z), no overflow
        return a, -a * (1.0 - a) / np.exp(theta[1])

    def _sides(self, X1, X2, theta):
        a1, d1 = self._above(X1, theta)
        a2, d2 = (a1, d1) if X2 is X1 else self._above(X2, theta)
        return a1, d1, a2, d2

    def __call__(self, X1, X2, theta):
        a1, _, a2, _ = self._sides(X1, X2, theta)
        K = self.kernel(X1, X2, theta[3:])
        if not (a1.any() or a2.any()):  # off: every input below the onset
            return K
        return self._times_scale(K, a1, a2, theta)

    def _scale(self, a1, a2, theta) -> np.ndarray:
        """S = b bᵀ + r² a aᵀ, (N1, N2)."""
        return np.outer(1.0 - a1, 1.0 - a2) + np.exp(2.0 * theta[2]) * np.outer(a1, a2)

    def _times_scale(self, M, a1, a2, theta) -> np.ndarray:
        """``M ∘ S`` in place, the same numbers as ``M * _scale(a1, a2, theta)`` (r² finite, as
        ML-II's bounds keep it): a row wholly below the onset (a = 0, most of them at a sharp
        step) is S's row b', one wholly above (a = 1) r² a', and only the rows on the step need
        the outer products (a fifth of the time of forming S: its N² products and sums dominated
        a cut GP's likelihood)."""
        r2 = np.exp(2.0 * theta[2])
        below, above = a1 == 0.0, a1 == 1.0
        np.multiply(M, 1.0 - a2, out=M, where=below[:, None])
        np.multiply(M, r2 * a2, out=M, where=above[:, None])
        on_step = np.flatnonzero(~(below | above))
        if len(on_step):
            M[on_step] *= self._scale(a1[on_step], a2, theta)
        return M

    def diag(self, X, theta):
        a, _ = self._above(X, theta)
        return ((1.0 - a) ** 2 + np.exp(2.0 * theta[2]) * a**2) * self.kernel.diag(X, theta[3:])

    def _head(self, X1, X2, theta, P) -> np.ndarray:
        """``Σ P ∘ ∂S/∂(c, log w, log r)`` with P = W ∘ k_0: by vector products, no N×N product."""
        a1, d1, a2, d2 = self._sides(X1, X2, theta)
        r2 = np.exp(2.0 * theta[2])
        Pa2, Pb2 = P @ a2, P @ (1.0 - a2)
        out = np.zeros(3)
        out[2] = 2.0 * r2 * (a1 @ Pa2)
        x1 = np.asarray(X1)[:, self.dim] - theta[0]
        x2 = np.asarray(X2)[:, self.dim] - theta[0]
        for p, (g1, g2) in enumerate(((d1, d2), (d1 * x1, d2 * x2))):
            if g1.any() or g2.any():  # ∂S = -g1 bᵀ - b g2ᵀ + r² (g1 aᵀ + a g2ᵀ)
                Pg2 = P @ g2
                out[p] = -(g1 @ Pb2) - ((1.0 - a1) @ Pg2) + r2 * (g1 @ Pa2 + a1 @ Pg2)
        return out

    def gradients(self, X, theta):
        a, d = self._above(X, theta)
        x = np.asarray(X)[:, self.dim] - theta[0]
        r2 = np.exp(2.0 * theta[2])
        S = self._scale(a, a, theta)
        K0 = self.kernel(X, X, theta[3:])
        for g in (d, d * x):
            yield (-np.outer(g, 1.0 - a) - np.outer(1.0 - a, g) + r2 * (np.outer(g, a) + np.outer(a, g))) * K0
        yield 2.0 * r2 * np.outer(a, a) * K0
        for g in self.kernel.gradients(X, theta[3:]):
            yield S * g

    def weighted_gradient(self, X1, X2, theta, W, K=None):
        a1, _, a2, _ = self._sides(X1, X2, theta)
        K0 = self.kernel(X1, X2, theta[3:])
        if not (a1.any() or a2.any()):  # off: k = k_0, zero gradient in c, w, r
            return np.concatenate([np.zeros(3), self.kernel.weighted_gradient(X1, X2, theta[3:], W, K0)])
        head = self._head(X1, X2, theta, W * K0)
        inner = self.kernel.weighted_gradient(X1, X2, theta[3:], self._times_scale(W.copy(), a1, a2, theta), K0)
        return np.concatenate([head, inner])

    def weighted_diag_gradient(self, X, theta, w):
        a, d = self._above(X, theta)
        r2 = np.exp(2.0 * theta[2])
        d0 = self.kernel.diag(X, theta[3:])
        x = np.asarray(X)[:, self.dim] - theta[0]
        ds = 2.0 * (r2 * a - (1.0 - a))  # ∂[(1-a)² + r² a²]/∂a
        head = [np.sum(w * d0 * ds * d), np.sum(w * d0 * ds * d * x), np.sum(w * d0 * 2.0 * r2 * a**2)]
        inner = self.kernel.weighted_diag_gradient(X, theta[3:], w * ((1.0 - a) ** 2 + r2 * a**2))
        return np.concatenate([head, inner])


def cut_along(kernels, inputs) -> list:
    """Each kernel wrapped in a :class:`Region` along its input column of ``inputs`` (None: not
    wrapped; a kernel that is already a Region is kept as it is)."""
    pairs = zip(kernels, inputs, strict=True)
    return [k if k is None or d is None or isinstance(k, Region) else Region(d, k) for k, d in pairs]


def cut_outputs(kernels, theta) -> list:
    """The outputs whose kernel is a :class:`Region` cut at an onset under ``theta`` (one parameter
    vector per kernel): not off (REGION_OFF)."""
    return [j for j, k in enumerate(kernels) if isinstance(k, Region) and theta[j][0] < REGION_OFF]


#: The onset of a Region kernel that is off: above every standardised input, so k = k_0.
REGION_OFF = 1e3
#: A Region kernel's width, in stds of its input: a step sharper than the samples' spacing along
#: it (a joint at 1 rad/s sampled at 100 Hz moves some 0.02 stds between samples).
REGION_WIDTH = 1e-3


#: A released length-scale (Guard.release_capped), in input stds: the kernel is constant along it.
RELEASED_LENGTHSCALE = 1e3


def is_lengthscale(name: str) -> bool:
    """True for a log length-scale parameter name (used by priors and bounds)."""
    return name.rsplit(".", 1)[-1].startswith("log_ell")


def is_amplitude(name: str) -> bool:
    """True for a log signal standard deviation (σ_z) parameter name."""
    return name.rsplit(".", 1)[-1] == "log_sigma_z"



def is_fixed(name: str) -> bool:
    """True for a parameter ML-II holds at its start (a Region kernel's onset and width)."""
    return name.rsplit(".", 1)[-1] in ("region_onset", "log_region_width")
