"""The semi-parametric GP estimator on plain arrays (robot-agnostic), thesis §3.3.

``SemiParametricGP(kernels, ...).fit(U, Y, F)`` learns hyperparameters by maximum marginal
likelihood (ML-II, optionally with priors = MAP) with analytic gradients, from the heuristic
initial values of §3.3.4, in log space with scipy's L-BFGS-B, then forms the posterior
(:mod:`diegocal.sgp.gp`). Inputs are standardised and feature columns scaled to unit RMS
internally; every attribute ending in ``_`` is in the caller's units.

Use it directly for models whose features are not a robot's torque regressor (e.g. the
forward reaction-wheel model of thesis eq. 3.28); :func:`diegocal.sgp.fit_dynamics` wraps it
for inverse dynamics.
"""

from __future__ import annotations

import warnings
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
from scipy.cluster.vq import kmeans2
from scipy.optimize import minimize

from diegocal.errors import FitError, NumericalError
from diegocal.evaluate import choose_by_validation  # noqa: F401 (re-exported: the guard's rule)
from diegocal.sgp.gp import Hyperparameters, fit_posterior, negative_log_likelihood
from diegocal.sgp.kernels import is_amplitude, is_lengthscale

LOG_BOUND = 12.0  # |log| of any hyperparameter relative to its scale
# L-BFGS-B stops when an iteration improves the objective by less than FTOL relative to |f|;
# scipy's default (2.2e-9) spends about half of the evaluations on the last 0.1 nat of a
# likelihood of several thousand nats (bench/bench_sgp_scale.py; held-out accuracy unchanged).
FTOL = 1e-6
# A released length-scale (Guard.release_capped), in input stds: the kernel is constant along it.
RELEASED_LENGTHSCALE = 1e3
# The stretches along the σ_z-ℓ ridge tried by Guard.extend_capped.
STRETCHES = 2.0 ** np.arange(1, 11)
# An input is "linear in the parametric part" when its column is in the span of the output's
# feature columns and a constant to this relative residual (rounding only: an exact column).
LINEAR_TOLERANCE = 1e-6


@dataclass(frozen=True)
class Guard:
    """Guards against the GP part soaking up physics the parametric part explains (all optional).

    Why it is needed: wherever a parametric term is a smooth function of the GP's inputs (gravity
    in q, friction in qd) the GP can carry part of it at nearly the same marginal likelihood, and
    along a trajectory every smooth function of time is a function of the state, so a flexible GP
    can even mimic terms in inputs it does not see (the motor command of the reaction wheel, in
    which eq. 3.28 is linear). In-sample this costs nothing; far from the data, where the GP
    reverts to its prior, the W it distorted predicts alone. :data:`diegocal.sgp.DEFAULT_GUARD`
    documents the default setting and the evidence for it.

    Attributes
    ----------
    max_lengthscale : float or None
        Upper bound on every length-scale, in units of the input's training std. Bounded, the GP
        reverts to its prior a few stds outside the data instead of extrapolating a trend or
        half-reverting, and cannot become a global smooth function competing with W.
    lengthscale_prior : (mean, std) or None
        Gaussian prior on log ℓ (ℓ in units of the input's std): MAP instead of ML-II.
    amplitude_prior : float or None
        Std of a Gaussian prior on log(σ_z / s), s the std of the residual of the parametric-only
        fit (it keeps σ_z at that size even where the GP is not needed; off by default).
    validation_fraction : float
        Size of the contiguous blocks (fraction of the samples, in time order) of a blocked
        cross-validation that chooses, per output, between the learnt hyperparameters, the
        released ones (``release_capped``) and a parametric-only fallback (PR's σ_w and σ_v, σ_z
        at its floor): an output whose cross-validated nMSE no GP lowers by more than one
        standard error falls back to PR (:meth:`~SemiParametricGP._validate`). The
        hyperparameters are learnt on all samples; each block is predicted by the posterior of
        the others.
    restarts : int
        Extra starts on top of the estimator's ``restarts``.
    fix_sigma_w : bool
        Keep σ_w at a large value (a flat prior on W) instead of learning it by ML-II.
    max_amplitude : float or None
        Upper bound on σ_z in units of the parametric-only fit's residual std: Z models the
        *deviations* from the parametric model (thesis §3.3), so it may not grow to the size of
        the physics.
    release_capped : bool
        With ``max_lengthscale`` and ``validation_fraction``: a third candidate for the blocked
        cross-validation, in which every input whose length-scale ends at the cap is *released*
        (ℓ fixed at RELEASED_LENGTHSCALE stds: the GP constant along it, as if it were not an
        input) and the other hyperparameters re-optimised under the cap. ARD's verdict "no
        structure at any scale the cap allows" then holds outside the data too: a capped
        irrelevant input (the reaction wheel's angle, which drifts far from its training range)
        makes the GP revert to 0 wherever it leaves the training range, dropping the deviation
        it models (the wheel's friction) although the deviation does not depend on that input.
        Released, not uncapped: a length-scale of some ten stds half-reverts at a pole-up
        angle 30 stds away and blew up a short reaction-wheel run (nMSE 0.059 against PR's 0.005).
    extend_capped : bool
        With ``max_lengthscale`` and ``validation_fraction``: a further candidate where the
        likelihood, not the cap, decides the limit of each capped length-scale (:meth:`~Semi
        ParametricGP._extend`): a capped input is released if that costs no likelihood, and the
        rest are stretched along the σ_z-ℓ ridge towards an SE kernel's *linear* limit while the
        likelihood rises. Why: an SE kernel carries a linear trend (viscous friction in a
        velocity) only on that ridge, where the likelihood is nearly flat and σ_z ≫ the residual,
        so the σ_z cap stops it at ℓ ≈ 3 stds and the GP reverts to 0 a few stds outside the data.
        Inputs in which the parametric part is exactly linear are released, not stretched, in the
        stretched trials. Offer it only when the parametric model has no viscous friction column:
        the 3-link arm, whose regressor has one, got slightly worse in 5 of 6 cells with it, with
        or without that release rule (horizontal joint 1: 0.00168 against 0.00138).
    """

    max_lengthscale: float | None = None
    lengthscale_prior: tuple[float, float] | None = None
    amplitude_prior: float | None = None
    validation_fraction: float = 0.0
    restarts: int = 0
    fix_sigma_w: bool = False
    max_amplitude: float | None = None
    release_capped: bool = False
    extend_capped: bool = False


class SemiParametricGP:
    """SGP regression with shared parameters W and one GP per output (thesis eq. 3.1-3.20).

    Parameters
    ----------
    kernels : list of Kernel or None, one per output; None means no GP for that output (PR)
    use_features : bool, False drops F (a zero-mean GP, thesis eq. 3.21)
    fit_sigma_w : bool, optimise σ_w (True) or keep the §3.3.4 "large" initial value
    restarts : int, extra optimisations from perturbed initial values (seeded)
    seed : int
    guard : Guard
    inference : "exact" or "sparse" (DTC/VFE with ``n_inducing`` k-means inducing inputs)
    n_inducing : int
    hyper_max : int, hyperparameters are learnt on at most this many samples (random subset)
    maxiter : int, L-BFGS-B iterations per start
    min_noise : float, floor of σ_v relative to std(y_j)
    jobs : int, optimise the starts in this many threads
    """

    def __init__(
        self,
        kernels,
        *,
        use_features: bool = True,
        fit_sigma_w: bool = True,
        restarts: int = 0,
        seed: int = 0,
        guard: Guard = Guard(),
        inference: str = "exact",
        n_inducing: int = 300,
        hyper_max: int = 1000,
        maxiter: int = 200,
        min_noise: float = 1e-4,
        jobs: int = 1,
    ):
        if inference not in ("exact", "sparse"):
            raise ValueError(f"inference must be 'exact' or 'sparse', got {inference!r}")
        self.kernels = list(kernels)
        self.use_features = use_features
        self.fit_sigma_w = fit_sigma_w
        self.restarts = int(restarts)
        self.seed = int(seed)
        self.guard = guard
        self.inference = inference
        self.n_inducing = int(n_inducing)
        self.hyper_max = int(hyper_max)
        self.maxiter = int(maxiter)
        self.min_noise = float(min_noise)
        self.jobs = max(1, int(jobs))

    # ------------------------------------------------------------------ scaling
    def _scale(self, U, F):
        return (U - self.u_mean_) / self.u_std_, F / self.f_scale_

    def _check(self, U, Y, F):
        U, Y, F = (np.asarray(x, float) for x in (U, Y, F))
        if U.ndim != 2 or Y.ndim != 2 or F.ndim != 3:
            raise ValueError(f"expected U (N, p), Y (N, n), F (N, n, m); got {U.shape}, {Y.shape}, {F.shape}")
        if not (len(U) == len(Y) == len(F)) or F.shape[1] != Y.shape[1] or Y.shape[1] != len(self.kernels):
            raise ValueError(f"inconsistent shapes U {U.shape}, Y {Y.shape}, F {F.shape}, {len(self.kernels)} kernels")
        if not self.use_features:
            F = F[:, :, :0]
        return U, Y, F

    # ------------------------------------------------------------------ fit
    def fit(
        self,
        U,
        Y,
        F,
        hyperparameters: Hyperparameters | None = None,
        inducing: np.ndarray | None = None,
    ) -> SemiParametricGP:
        """Learn hyperparameters (unless given) and the posterior.

        U : (N, p) inputs; Y : (N, n) observations (y's unit); F : (N, n, m) features.
        ``hyperparameters``/``inducing`` (scaled inputs, (M, p)) restore a saved fit exactly.
        """
        U, Y, F = self._check(U, Y, F)
        N, n = Y.shape
        if N < 3:
            raise FitError(f"need at least 3 samples to fit, got {N}")
        self.u_mean_ = U.mean(0)
        self.u_std_ = np.where(U.std(0) > 0, U.std(0), 1.0)
        rms = np.sqrt(np.mean(F**2, axis=(0, 1))) if F.shape[2] else np.zeros(0)
        self.f_scale_ = np.where(rms > 0, rms, 1.0)
        Us, Fs = self._scale(U, F)
        self.y_std_ = np.where(Y.std(0) > 0, Y.std(0), 1.0)
        rng = np.random.default_rng(self.seed)
        if hyperparameters is None:
            hyperparameters = self._learn(Us, Y, Fs, rng)
        self.hyper_ = hyperparameters
        if inducing is None and self.inference == "sparse" and any(k is not None for k in self.kernels):
            inducing = self._inducing(Us, rng)
        self.inducing_ = inducing
        self.posterior_ = fit_posterior(self.kernels, Us, Y, Fs, hyperparameters, inducing)
        w = self.posterior_.w_mean / self.f_scale_
        cov = self.posterior_.w_cov / np.outer(self.f_scale_, self.f_scale_)
        self.w_, self.w_cov_ = w, cov
        self.log_likelihood_ = self.posterior_.log_likelihood
        return self

    def _inducing(self, Us, rng):
        M = min(self.n_inducing, len(Us))
        if M >= len(Us):
            return Us.copy()
        start = Us[rng.choice(len(Us), M, replace=False)]
        with warnings.catch_warnings():  # an empty cluster keeps its start, a training input: fine
            warnings.filterwarnings("ignore", "One of the clusters is empty", UserWarning)
            centres, _ = kmeans2(Us, start, iter=10, minit="matrix", seed=rng)
        return centres

    def _initial(self, Us, Y, Fs) -> tuple[Hyperparameters, np.ndarray]:
        """§3.3.4 heuristics: σ_v² = var(y)/100, σ_z² = var(y), ℓ = spread of u, σ_w large."""
        var = self.y_std_**2
        resid = self._parametric_residual_std(Y, Fs)
        thetas = []
        for j, k in enumerate(self.kernels):
            if k is None:
                thetas.append(np.zeros(0))
                continue
            t = np.zeros(k.n_params)  # ℓ = 1 input std (the inputs are standardised)
            for i, name in enumerate(k.names):
                if is_amplitude(name):
                    t[i] = 0.5 * np.log(var[j])
            thetas.append(t)
        # "some large number": 10 × std(y) in unit-RMS feature coordinates; 1000 × when fixed (flat)
        sigma_w = (1e3 if self.guard.fix_sigma_w else 10.0) * float(np.max(self.y_std_))
        has_gp = np.array([k is not None for k in self.kernels])
        # noise: var/100 under a GP; the parametric residual when the GP is absent (PR)
        sv = np.where(has_gp, 0.1 * self.y_std_, np.maximum(resid, 1e-3 * self.y_std_))
        return Hyperparameters(np.log(sigma_w), np.log(sv), tuple(thetas)), resid

    def _parametric_residual_std(self, Y, Fs):
        if Fs.shape[2] == 0:
            return self.y_std_.copy()
        A = Fs.reshape(-1, Fs.shape[2])
        w, *_ = np.linalg.lstsq(A, Y.reshape(-1), rcond=None)
        r = Y - Fs @ w
        return np.maximum(r.std(0), 1e-6 * self.y_std_)

    def _bounds(self, hp0: Hyperparameters, resid):
        n = len(self.kernels)
        lo, hi = [], []
        if self.fit_sigma_w and not self.guard.fix_sigma_w and self.use_features:
            lo.append(hp0.log_sigma_w - LOG_BOUND)
            hi.append(hp0.log_sigma_w + LOG_BOUND)
        else:
            lo.append(hp0.log_sigma_w)
            hi.append(hp0.log_sigma_w)
        floor = np.log(self.min_noise * self.y_std_)
        lo += list(floor)
        hi += list(np.log(self.y_std_) + 2.0)
        g = self.guard
        for j in range(n):
            k = self.kernels[j]
            if k is None:
                continue
            for name in k.names:
                if is_lengthscale(name):
                    lo.append(np.log(1e-2))
                    hi.append(np.log(g.max_lengthscale) if g.max_lengthscale else np.log(1e3))
                else:
                    lo.append(np.log(1e-6 * self.y_std_[j]))
                    top = np.log(self.y_std_[j]) + 3.0
                    if g.max_amplitude is not None and is_amplitude(name) and self.use_features:
                        top = min(top, np.log(g.max_amplitude * resid[j]))
                    hi.append(top)
        return list(zip(lo, hi, strict=True))

    def _slots(self):
        """Per output: (j, offset of its kernel's log-parameters in the packed vector, their
        names); the names are empty for an output without GP."""
        k = 1 + len(self.kernels)
        for j, kern in enumerate(self.kernels):
            names = kern.names if kern is not None else ()
            yield j, k, names
            k += len(names)

    def _linear_slots(self, Us, Fs) -> set[int]:
        """Packed indices of the length-scales of inputs in which the output's parametric part is
        exactly linear: the input column lies in the span of the output's feature columns and a
        constant (relative residual under LINEAR_TOLERANCE), e.g. the wheel angle, a column of
        eq. 3.28, or a joint velocity beside a viscous friction column."""
        out = set()
        for j, k, names in self._slots():
            if not names:
                continue
            A = np.column_stack([Fs[:, j, :], np.ones(len(Fs))])
            for i, d in enumerate(self.kernels[j].lengthscale_inputs):
                if d is None:
                    continue
                u = Us[:, d] - Us[:, d].mean()
                coef, *_ = np.linalg.lstsq(A, Us[:, d], rcond=None)
                if np.linalg.norm(Us[:, d] - A @ coef) <= LINEAR_TOLERANCE * np.linalg.norm(u):
                    out.add(k + i)
        return out

    def _capped(self, log_lengthscale) -> bool:
        return log_lengthscale >= np.log(self.guard.max_lengthscale) - 1e-3

    def _prior(self, vec, resid):
        """Negative log prior of the guard's priors, and its gradient (0 when no prior is set)."""
        g = self.guard
        val, grad = 0.0, np.zeros_like(vec)
        for j, k, names in self._slots():
            for i, name in enumerate(names):
                x = vec[k + i]
                if is_lengthscale(name) and g.lengthscale_prior is not None:
                    mu, sd = g.lengthscale_prior
                    val += 0.5 * ((x - mu) / sd) ** 2
                    grad[k + i] += (x - mu) / sd**2
                elif is_amplitude(name) and g.amplitude_prior is not None:
                    mu, sd = np.log(resid[j]), g.amplitude_prior
                    val += 0.5 * ((x - mu) / sd) ** 2
                    grad[k + i] += (x - mu) / sd**2
        return val, grad

    def _starts(self, x0, bounds, resid, rng, n_extra):
        """Starts: §3.3.4's; a short-length-scale one (ℓ = 0.3 input std); a parametric-first
        one (σ_z and σ_v at the parametric fit's residual: the basin where W carries the
        physics); then random perturbations of §3.3.4's."""
        lo, hi = np.array([b[0] for b in bounds]), np.array([b[1] for b in bounds])

        def variant(ell=None, amp=None):
            x = x0.copy()
            for j, k, names in self._slots():
                if names and amp is not None:
                    x[1 + j] = np.log(amp[j] / 3.0)
                for i, name in enumerate(names):
                    if is_lengthscale(name) and ell is not None:
                        x[k + i] = np.log(ell)
                    elif is_amplitude(name) and amp is not None:
                        x[k + i] = np.log(amp[j])
            return x

        starts = [x0, variant(ell=0.3), variant(amp=resid)][: 1 + n_extra]
        starts += [x0 + rng.normal(0.0, 1.0, x0.size) for _ in range(n_extra - 2)]
        return [np.clip(s, lo, hi) for s in starts]

    def _optimise(self, start, bounds, sizes, resid, U, Y, F, maxiter):
        def objective(vec):
            try:
                f, gr = negative_log_likelihood(vec, self.kernels, U, Y, F, sizes)
            except NumericalError:
                return 1e25, np.zeros_like(vec)
            pv, pg = self._prior(vec, resid)
            return f + pv, gr + pg

        res = minimize(
            objective,
            start,
            jac=True,
            method="L-BFGS-B",
            bounds=bounds,
            options={"maxiter": maxiter, "ftol": FTOL},
        )
        ok = np.isfinite(res.fun) and res.fun < 1e24
        return (float(res.fun), res.x) if ok else None

    def _learn(self, Us, Y, Fs, rng) -> Hyperparameters:
        """ML-II (or MAP with the guard's priors) from several starts; the best objective wins.

        With ``guard.validation_fraction`` the GP then has to earn its place, output by output,
        in a blocked cross-validation (:meth:`_validate`) against a parametric-only fallback
        (σ_z at its floor, σ_w and σ_v as PR learns them; SGP → PR for that output) and, with
        ``guard.release_capped``, against the hyperparameters with the capped inputs released.
        """
        N = len(Us)
        idx = np.arange(N)
        if N > self.hyper_max:
            idx = np.sort(rng.choice(N, self.hyper_max, replace=False))
        hp0, resid = self._initial(Us[idx], Y[idx], Fs[idx])
        sizes = [0 if k is None else k.n_params for k in self.kernels]
        bounds = self._bounds(hp0, resid)
        lo, hi = [b[0] for b in bounds], [b[1] for b in bounds]
        has_gp = any(k is not None for k in self.kernels)
        n_extra = self.restarts + (self.guard.restarts if has_gp else 0)
        x0 = np.clip(hp0.pack(), lo, hi)
        starts = self._starts(x0, bounds, resid, rng, n_extra if has_gp else 0)
        self.n_starts_ = len(starts)
        data = Us[idx], Y[idx], Fs[idx]

        def run(s):
            return self._optimise(s, bounds, sizes, resid, *data, self.maxiter)

        if self.jobs > 1 and len(starts) > 1:  # independent starts in threads (LAPACK drops the GIL)
            with ThreadPoolExecutor(max_workers=self.jobs) as pool:
                results = list(pool.map(run, starts))
        else:
            results = [run(s) for s in starts]
        candidates = [c for c in results if c]
        if not candidates:
            raise NumericalError(
                "hyperparameter optimisation failed from every start; "
                "raise min_noise or check the data for repeated samples"
            )
        self.objective_, x = min(candidates, key=lambda c: c[0])
        f = self.guard.validation_fraction
        folds = int(round(1.0 / f)) if f > 0 else 0
        if has_gp and folds >= 2 and len(idx) >= 3 * folds:
            options = {"learnt": x}
            if self.guard.max_lengthscale and self.guard.release_capped:
                released = self._release(
                    x, bounds, lambda s, b: self._optimise(s, b, sizes, resid, *data, self.maxiter)
                )
                if released is not None:
                    options["released"] = released
            if self.guard.max_lengthscale and self.guard.extend_capped:
                extended = self._extend(x, sizes, data)
                if extended is not None:
                    options["extended"] = extended
            options["parametric"] = self._parametric_only(x0, resid, bounds, data)
            blocks = np.array_split(idx, folds)  # contiguous in time order
            x = self._validate(options, blocks, Us, Y, Fs, sizes)
        return Hyperparameters.unpack(x, sizes)

    def _release(self, x, bounds, optimise) -> np.ndarray | None:
        """Guard.release_capped: the length-scales at the cap fixed at RELEASED_LENGTHSCALE and
        the other hyperparameters re-optimised from ``x`` by ``optimise(start, bounds)``; None
        when no length-scale sits at the cap or the optimisation fails."""
        big = np.log(RELEASED_LENGTHSCALE)
        start, new_bounds, any_capped = x.copy(), list(bounds), False
        for _, k, names in self._slots():
            for i, name in enumerate(names):
                if is_lengthscale(name) and self._capped(x[k + i]):
                    start[k + i] = big
                    new_bounds[k + i] = (big, big)
                    any_capped = True
        result = optimise(start, new_bounds) if any_capped else None
        return None if result is None else result[1]

    def _extend(self, x, sizes, data) -> np.ndarray | None:
        """Guard.extend_capped: where ML-II presses a length-scale against the cap, take the limit
        the likelihood points to, output by output, without re-optimising.

        1. Release each capped input (ℓ → RELEASED_LENGTHSCALE: the GP constant along it) whose
           release does not lower the marginal likelihood.
        2. Stretch along the ridge: σ_z and every length-scale not released, times K in
           STRETCHES (2 to 1024); keep the K of highest likelihood, if any beats the unstretched.
           An SE kernel whose length-scales all exceed the data's spread is, to second order, a
           constant plus a *linear* kernel of slope variance σ_z²/ℓ² (unchanged by the stretch):
           it then extrapolates a linear trend (viscous friction in a velocity) instead of
           reverting to 0 a few stds outside the data. A stretched trial releases the inputs in
           which the parametric part is already linear (:meth:`_linear_slots`): there the GP's
           linear trend is W's own column, the two trade at equal likelihood, and the split
           extrapolates wherever the input leaves the data. (Reaction wheel, seed 1: the wheel
           angle, a column of eq. 3.28 with true coefficient 0, stretched to ℓ = 12 stds beside
           W's coefficient 0.13; at 8 training stds on the pole-down test the wheel axis's nMSE
           was 0.0020, against 0.0004 with the angle released.)
        None when nothing changed."""
        U, Y, F = data
        linear = self._linear_slots(U, F)

        def nll(vec):
            try:
                return negative_log_likelihood(vec, self.kernels, U, Y, F, sizes, grad=False)
            except NumericalError:
                return np.inf

        big = np.log(RELEASED_LENGTHSCALE)
        x, best = x.copy(), nll(x)
        start = x.copy()
        for _, k, names in self._slots():
            scales = [k + i for i, name in enumerate(names) if is_lengthscale(name)]
            amps = [k + i for i, name in enumerate(names) if is_amplitude(name)]
            for i in scales:  # 1. release
                if self._capped(x[i]):
                    trial = x.copy()
                    trial[i] = big
                    f = nll(trial)
                    if f <= best:
                        x, best = trial, f
            free = [i for i in scales if x[i] < big - 1e-6]
            base = x.copy()
            for K in STRETCHES if free and amps else ():  # 2. stretch
                trial = base.copy()
                trial[amps] += np.log(K)
                trial[free] = np.minimum(trial[free] + np.log(K), big)
                trial[[i for i in free if i in linear]] = big
                f = nll(trial)
                if f < best:
                    x, best = trial, f
        return None if np.array_equal(x, start) else x

    def _parametric_only(self, x0, resid, bounds, data) -> np.ndarray:
        """The parametric-only fallback, PR's hyperparameters: σ_z at its floor, σ_w and σ_v
        learnt by ML-II without the GPs (cheap: no N×N matrix). σ_w matters: the weakly excited
        directions of W (the 3-link arm's gravity parameters on a horizontal figure-eight) are
        held by its shrinkage; at §3.3.4's "large" initial σ_w, 10× PR's learnt one, the
        fallback predicted the arm's vertical joint 1 at nMSE 4.4 against PR's 0.028."""
        n = len(self.kernels)
        U, Y, F = data
        head = slice(0, 1 + n)  # packed [log σ_w, log σ_v per output]

        def objective(vec):
            return negative_log_likelihood(vec, [None] * n, U, Y, F, [0] * n)

        start = np.concatenate([x0[:1], np.log(resid)])
        start = np.clip(start, [b[0] for b in bounds[head]], [b[1] for b in bounds[head]])
        out = x0.copy()
        try:
            res = minimize(objective, start, jac=True, method="L-BFGS-B", bounds=bounds[head])
            out[head] = res.x
        except NumericalError:
            out[head] = start
        for _, k, names in self._slots():
            for i, name in enumerate(names):
                if is_amplitude(name):
                    out[k + i] = bounds[k + i][0]
        return out

    def _validate(self, options: dict, blocks, Us, Y, Fs, sizes) -> np.ndarray:
        """Per output, the hyperparameters of ``options`` (label -> vector: learnt, [released,
        extended,] parametric) that predict held-out samples best: blocked cross-validation, each
        contiguous block of ``blocks`` predicted by the posterior of the others, nMSE averaged
        over the blocks (one held-out block could be unrepresentative, e.g. a robot at rest at
        the end of a run). Ties go to the earlier option; σ_w is the earliest chosen option's.

        A GP must earn its place: an output keeps one only if it beats the parametric fallback
        by more than one standard error of their paired per-block difference
        (:func:`choose_by_validation`). Why: W is shared, and a GP on an output that PR already
        fits to the noise lets W drift in directions the training run barely excites, at no
        cost in-sample or in the cross-validation (3-link arm at 1000 samples, seed 0: joint 1's
        GP beat PR by 0.4 % of its CV error, and the vertical figure-eight's joint 1 was
        predicted at nMSE 6.8 against PR's 0.15).
        Sets ``selection_`` (label per output) and ``validation_scores_`` (label -> (n,))."""
        labels, options = list(options), list(options.values())
        per_block = np.zeros((len(options), len(blocks), Y.shape[1]))
        for c, vec in enumerate(options):
            hp = Hyperparameters.unpack(vec, sizes)
            for b, val_idx in enumerate(blocks):
                fit_idx = np.concatenate(blocks[:b] + blocks[b + 1 :])
                try:
                    post = fit_posterior(self.kernels, Us[fit_idx], Y[fit_idx], Fs[fit_idx], hp)
                except NumericalError:
                    per_block[c] = np.inf
                    break
                mean, _, _ = post.predict(Us[val_idx], Fs[val_idx])
                per_block[c, b] = np.mean((mean - Y[val_idx]) ** 2, axis=0) / self.y_std_**2
        self.validation_scores_ = dict(zip(labels, per_block.mean(axis=1), strict=True))
        choice = choose_by_validation(per_block, labels.index("parametric"))
        self.selection_ = tuple(labels[c] for c in choice)
        out = options[int(choice.min())].copy()
        for j, k, names in self._slots():
            out[1 + j] = options[choice[j]][1 + j]
            out[k : k + len(names)] = options[choice[j]][k : k + len(names)]
        return out

    # ------------------------------------------------------------------ predict
    def predict(self, U, F) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Posterior mean (Nq, n), latent variance (Nq, n) and parametric part f ŵ (Nq, n).

        The observation's predictive variance adds ``noise_var_`` (n,) to the latent one.
        """
        U, F = np.asarray(U, float), np.asarray(F, float)
        if not self.use_features:
            F = F[:, :, :0]
        Us, Fs = self._scale(U, F)
        return self.posterior_.predict(Us, Fs)

    @property
    def noise_var_(self) -> np.ndarray:
        return self.posterior_.noise_var
