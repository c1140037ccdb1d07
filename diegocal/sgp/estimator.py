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

import functools

import numpy as np

from diegocal.errors import FitError, NumericalError
from diegocal.evaluate import choose_by_validation  # noqa: F401 (re-exported: the guard's rule)
from diegocal.parallel import single_threaded, thread_map
from diegocal.sgp.blocks import input_scaling
from diegocal.sgp.gp import (
    Hyperparameters,
    fit_posterior,
    parametric_robust_w_cov,
    per_output,
    w_variance,
)
from diegocal.sgp.guard import GuardCandidates
from diegocal.sgp.guard_options import PARAMETRIC, TWO_STAGE, Guard, Stages
from diegocal.sgp.inducing import MAX_POINTS, SPARSE_TOLERANCE, greedy_inducing
from diegocal.sgp.kernels import REGION_OFF, REGION_WIDTH, Region, cut_along
from diegocal.sgp.pr_sums import GramSums, posterior_from_sums
from diegocal.sgp.starts import MLStarts
from diegocal.sgp.subnormals import flushed

__all__ = ["Guard", "SemiParametricGP", "Stages"]

CHUNK_SAMPLES = 20_000  # samples whose features fit_in_chunks builds at once



class SemiParametricGP(GuardCandidates, MLStarts):
    """SGP regression with shared parameters W and one GP per output (thesis eq. 3.1-3.20).

    Parameters
    ----------
    kernels : list of Kernel or None, one per output; None means no GP for that output (PR)
    use_features : bool, False drops F (a zero-mean GP, thesis eq. 3.21)
    fit_sigma_w : bool, optimise σ_w (True) or keep the §3.3.4 "large" initial value
    restarts : int, extra optimisations from perturbed initial values (seeded)
    seed : int
    guard : Guard
    inference : "exact" or "sparse" (DTC/VFE, inducing inputs per output by greedy conditional
        variance, :mod:`diegocal.sgp.inducing`)
    n_inducing : int, the most inducing inputs per output
    sparse_tolerance : float, add inducing inputs until the mean prior variance they miss is at
        most this fraction of σ_v²
    hyper_max : int, hyperparameters are learnt on at most this many samples (random subset)
    maxiter : int, L-BFGS-B iterations per start
    min_noise : float, floor of σ_v relative to std(y_j)
    jobs : int, threads for independent work: the hyperparameter starts, the cross-validation
        fits, the outputs' inducing inputs and factorisations (each on one BLAS thread,
        :mod:`diegocal.parallel`)
    progress : callable(stage: str, done: int, total: int) or None, told as each hyperparameter
        start, the cross-validation and the posterior finish (the CLI's progress bar)
    region_inputs : tuple of (int or None) per output, or None: the input column along which the
        two-stage candidate's GP of that output may be cut in two (its joint's angle:
        :class:`~diegocal.sgp.kernels.Region`, :meth:`~diegocal.sgp.region.RegionScan._region_scan`)
    screen_starts : bool, screen the ML-II starts on a few samples and refine the best
        (:meth:`_screen`). The model sets it where the guard's cross-validation judges the result
        (SGP with the guard): a screened start can land in a worse basin, and nothing else would
        catch it (PRGP on the scale bench's arm fell back to PR's figure at 2,000 and 5,000
        samples, 0.0083 against 0.0049 and 0.0046 with every start run in full).
    """

    def __init__(
        self,
        kernels,
        *,
        use_features: bool = True,
        fit_sigma_w: bool = True,
        restarts: int = 0,
        seed: int = 0,
        guard: Guard = Guard(),  # noqa: B008 (frozen dataclass)
        inference: str = "exact",
        n_inducing: int = MAX_POINTS,
        sparse_tolerance: float = SPARSE_TOLERANCE,
        hyper_max: int = 1000,
        maxiter: int = 200,
        min_noise: float = 1e-4,
        jobs: int = 1,
        progress=None,
        region_inputs=None,
        screen_starts: bool = False,
    ):
        if inference not in ("exact", "sparse"):
            raise ValueError(f"inference must be 'exact' or 'sparse', got {inference!r}")
        self.kernels = list(kernels)
        self.screen_starts = bool(screen_starts)
        self.use_features = use_features
        self.fit_sigma_w = fit_sigma_w
        self.restarts = int(restarts)
        self.seed = int(seed)
        self.guard = guard
        self.inference = inference
        self.n_inducing = int(n_inducing)
        self.sparse_tolerance = float(sparse_tolerance)
        self.hyper_max = int(hyper_max)
        self.maxiter = int(maxiter)
        self.min_noise = float(min_noise)
        self.jobs = max(1, int(jobs))
        self.progress = progress
        self.region_inputs = None if region_inputs is None else tuple(region_inputs)
        self._runs: list = []  # the last fit's L-BFGS-B runs (MLStarts._ran)

    def _say(self, stage: str, done: int, total: int) -> None:
        if self.progress is not None:
            self.progress(stage, done, total)

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
    def _standardise(self, U, Y, F, overwrite_features: bool = False):
        """Check the arrays, set the scaling attributes; returns U, Y, F, Us, Fs.

        With ``overwrite_features`` and no kernel on any output (a PR fit, which never reads the
        unscaled F again), Fs is F scaled in F's own memory, so that a long log's features are
        held once; the returned F is then Fs too."""
        U, Y, F = self._check(U, Y, F)
        N, n, m = F.shape  # the columns' RMS over samples and outputs, without a squared copy of F
        self._set_scaling(U, Y, np.sqrt(np.einsum("tjm,tjm->m", F, F) / (N * n)) if m else np.zeros(0))
        self._raw = (U, F)  # the two-stage candidate's GP scales them as this estimator does
        if overwrite_features and all(k is None for k in self.kernels) and F.flags.writeable:
            F = np.divide(F, self.f_scale_, out=F)
            self._raw = None
            return U, Y, F, (U - self.u_mean_) / self.u_std_, F
        return (U, Y, F, *self._scale(U, F))

    def _set_scaling(self, U, Y, rms) -> None:
        """The scaling attributes from the inputs U (N, p), the outputs Y (N, n) and the feature
        columns' RMS over samples and outputs (m,)."""
        if len(Y) < 3:
            raise FitError(f"need at least 3 samples to fit, got {len(Y)}")
        self.u_mean_, self.u_std_ = input_scaling(U)
        self.f_scale_ = np.where(rms > 0, rms, 1.0)
        self.y_std_ = np.where(Y.std(0) > 0, Y.std(0), 1.0)

    def _keep(self, source) -> None:
        """W's estimate (caller's units) from the posterior ``source`` that predicts it, and the
        likelihood; the raw arrays let go."""
        self._say("posterior", 1, 1)
        self._raw = None
        self.w_ = source.w_mean / self.f_scale_
        self.w_cov_ = source.w_cov / np.outer(self.f_scale_, self.f_scale_)
        self.log_likelihood_ = self.posterior_.log_likelihood

    @single_threaded  # outermost: BLAS threads made when its limit is lifted start unflushed
    @flushed()
    def learn(self, U, Y, F, start: Hyperparameters | None = None) -> Hyperparameters:
        """The hyperparameters :meth:`fit` would learn, without the posterior (arrays as in fit);
        ``start``: one ML-II start from these instead of §3.3.4's heuristics and the restarts."""
        _, Y, _, Us, Fs = self._standardise(U, Y, F)
        self.stages_ = None
        return self._learn(Us, Y, Fs, np.random.default_rng(self.seed), start)

    @single_threaded
    @flushed()
    def fit(
        self,
        U,
        Y,
        F,
        hyperparameters: Hyperparameters | None = None,
        inducing=None,
        stages: Stages | None = None,
        residual_inducing=None,
        overwrite_features: bool = False,
    ) -> SemiParametricGP:
        """Learn hyperparameters (unless given) and the posterior.

        U : (N, p) inputs; Y : (N, n) observations (y's unit); F : (N, n, m) features.
        ``hyperparameters``/``inducing`` (scaled inputs: one (M, p) array, or per output an
        (M_j, p) array or None, :func:`~diegocal.sgp.gp.per_output`), ``stages`` and
        ``residual_inducing`` (the two-stage GPs' inducing inputs) restore a saved fit exactly.
        ``overwrite_features``: where no output has a kernel, F (float64) may be scaled in place
        and is garbage afterwards (as scipy's ``overwrite_a``): one copy of F less.
        """
        U, Y, F, Us, Fs = self._standardise(U, Y, F, overwrite_features)
        n = Y.shape[1]
        rng = np.random.default_rng(self.seed)
        self.stages_ = stages
        if hyperparameters is None:
            hyperparameters = self._learn(Us, Y, Fs, rng)  # sets stages_ (Guard.two_stage)
        else:  # a model saved before its kernels were Region kernels: the onset off
            hyperparameters = with_region_off(hyperparameters, self.kernels)
        self.hyper_ = hyperparameters
        kernels = self._joint_kernels()
        if inducing is None and self.inference == "sparse" and any(k is not None for k in kernels):
            inducing = self._inducing(Us, hyperparameters, rng, kernels)
        self.inducing_ = None if inducing is None else per_output(inducing, n)
        self.posterior_ = fit_posterior(kernels, Us, Y, Fs, hyperparameters, inducing, jobs=self.jobs)
        self._fit_stages(U, Y, F, Us, Fs, residual_inducing)
        joint = self.pr_posterior_ is None or self._modes().count("joint")
        self._keep(self.posterior_ if joint else self.pr_posterior_)
        return self

    @single_threaded
    @flushed()
    def fit_in_chunks(self, U, Y, features, hyperparameters: Hyperparameters | None = None) -> SemiParametricGP:
        """:meth:`fit` for PR (no kernel on any output) without the features held whole:
        ``features(rows)`` gives F (len(rows), n, m) of the samples ``rows`` (a slice, or sorted
        indices: the hyperparameter subset), called CHUNK_SAMPLES samples at a time in order.
        The posterior comes from per-block Gram sums (:mod:`diegocal.sgp.pr_sums`): the same
        numbers as :meth:`fit` up to the order of the sums."""
        if any(k is not None for k in self.kernels) or not self.use_features:
            raise ValueError("fit_in_chunks fits PR only: no kernel on any output, features used")
        U, Y = np.asarray(U, float), np.asarray(Y, float)
        N, n = Y.shape
        sums = None
        for i in range(0, N, CHUNK_SAMPLES):
            F = np.asarray(features(slice(i, min(i + CHUNK_SAMPLES, N))), float)
            sums = sums or GramSums(N, n, F.shape[2])
            sums.add(F, Y[i : i + CHUNK_SAMPLES])
        self._set_scaling(U, Y, sums.feature_rms() if sums else np.zeros(0))
        Us = (U - self.u_mean_) / self.u_std_
        rng = np.random.default_rng(self.seed)
        self.stages_ = None
        if hyperparameters is None:  # the subset fit() would learn on, drawn from the same stream
            idx = self._hyper_subset(N, rng)
            hyperparameters = self._learn(Us[idx], Y[idx], features(idx) / self.f_scale_, rng)
        self.hyper_ = hyperparameters
        self.inducing_ = None  # every block exact (no GP), as fit() leaves it
        self.posterior_ = posterior_from_sums(sums.scaled(self.f_scale_), Us, hyperparameters)
        self.pr_posterior_ = self.residual_ = self.pr_w_cov_robust_ = None
        self._keep(self.posterior_)
        return self

    def _modes(self) -> list:
        """Per output: "joint" (the joint posterior predicts it), TWO_STAGE or PARAMETRIC."""
        n = len(self.kernels)
        return ["joint"] * n if self.stages_ is None else [self.stages_.mode(j) for j in range(n)]

    def _joint_kernels(self) -> list:
        """The joint posterior's kernels: None for the outputs the stages predict (PR rows of W)."""
        return [k if m == "joint" else None for k, m in zip(self.kernels, self._modes(), strict=True)]

    def _fit_stages(self, U, Y, F, Us, Fs, residual_inducing) -> None:
        """``pr_posterior_`` (PR) when an output is not joint, ``residual_`` (the GPs on PR's
        residual, a :class:`SemiParametricGP` without features) when one is TWO_STAGE.

        W's robust covariance per output: a TWO_STAGE output's from what both stages leave
        (:func:`~diegocal.sgp.gp.parametric_robust_w_cov`) on its GP's data, PR's own
        (``pr_w_cov_robust_``) beyond them (:meth:`_two_stage_w_variance`); a PARAMETRIC one's
        PR's own, as PR has it: an output that falls back is PR, its band too. (From what both
        stages leave, the joint-3 GP on PR's residual took the friction's share out of the W
        variance that joint 2 needs: issue #14's arm, 200 samples, run 5, joint 2's ±2σ coverage
        0.66 against PR's 0.95.)"""
        modes = self._modes()
        self.pr_posterior_ = self.residual_ = self.pr_w_cov_robust_ = None
        if all(m == "joint" for m in modes):
            return
        self.pr_posterior_, res = self._pr_residual(self.stages_.pr, Us, Y, Fs)
        if TWO_STAGE in modes:
            kernels = [k if m == TWO_STAGE else None for k, m in zip(self.kernels, modes, strict=True)]
            est = self._residual_estimator(kernels)
            self.residual_ = est.fit(U, res, F, self.stages_.residual, residual_inducing)
            own = self.pr_w_cov_robust_ = self.pr_posterior_.w_cov_robust
            if own is not None:
                left = res - self.residual_.predict(U, F, variance=False)[0]
                both = parametric_robust_w_cov(self.pr_posterior_, Fs, left)
                self.pr_posterior_.w_cov_robust = np.stack([both if m == TWO_STAGE else own for m in modes])

    def _residual_estimator(self, kernels=None, inference=None, jobs=None) -> SemiParametricGP:
        """The two-stage candidate's GPs on PR's residual: PRGP's second stage with this
        estimator's kernels and settings, its length-scales under the guard's cap (no features)."""
        say = self.progress
        kernels = self.kernels if kernels is None else kernels
        if self.region_inputs is not None:
            kernels = cut_along(kernels, self.region_inputs)
        return SemiParametricGP(
            kernels,
            use_features=False,
            restarts=self.restarts,
            seed=self.seed,
            inference=self.inference if inference is None else inference,
            n_inducing=self.n_inducing,
            sparse_tolerance=self.sparse_tolerance,
            hyper_max=self.hyper_max,
            maxiter=self.maxiter,
            min_noise=self.min_noise,
            jobs=self.jobs if jobs is None else jobs,
            progress=None if say is None else (lambda stage, d, t: say(f"{stage}, GP on PR's residual", d, t)),
            guard=Guard(max_lengthscale=self.guard.max_lengthscale),
            screen_starts=self.screen_starts,
        )

    def _inducing(self, Us, hp: Hyperparameters, rng, kernels=None) -> list:
        """Per output, inducing inputs by greedy conditional variance (:mod:`diegocal.sgp.inducing`)
        until the mean missed prior variance is ``sparse_tolerance`` σ_v² (at most ``n_inducing``
        points); None (an exact block) for an output without GP or one that needs more than half
        of the samples (then the exact factor is as cheap)."""
        kernels = self.kernels if kernels is None else kernels
        pool_seeds = rng.integers(2**32, size=len(kernels))  # one stream per output: any jobs

        def select(j):
            k = kernels[j]
            if k is None:
                return None
            sel = greedy_inducing(
                k,
                hp.theta[j],
                Us,
                float(np.exp(2.0 * hp.log_sigma_v[j])),
                tolerance=self.sparse_tolerance,
                max_points=self.n_inducing,
                rng=np.random.default_rng(pool_seeds[j]),
            )
            return sel.points if len(sel.points) <= len(Us) // 2 else None

        return thread_map(select, range(len(self.kernels)), self.jobs)

    @property
    def sparse_gap_(self) -> np.ndarray:
        """(n,) per output, the prior variance per training sample its inducing inputs miss, in
        units of σ_v² (0 for an exact block): near 0, the sparse posterior is the exact one."""
        return np.array([getattr(b, "gap", 0.0) for b in self.posterior_.blocks])

    @property
    def n_inducing_(self) -> np.ndarray:
        """(n,) inducing inputs per output (0 for an exact block)."""
        return np.array([0 if z is None else len(z) for z in (self.inducing_ or [None] * len(self.kernels))])

    def _hyper_subset(self, N: int, rng) -> np.ndarray:
        """The samples (sorted indices) the hyperparameters are learnt on: at most hyper_max."""
        if N > self.hyper_max:
            return np.sort(rng.choice(N, self.hyper_max, replace=False))
        return np.arange(N)

    def _learn(self, Us, Y, Fs, rng, start: Hyperparameters | None = None) -> Hyperparameters:
        """ML-II (or MAP with the guard's priors) from several starts; the best objective wins.
        With ``screen_starts``, where the hyperparameter subset holds more than 2·SCREEN_SAMPLES
        samples, the starts are screened on SCREEN_SAMPLES of them and only the best is refined
        (:meth:`_screen`; the next where its refinement fails). ``n_starts_`` counts the starts,
        screened or not.

        With ``guard.validation_fraction`` the GP then has to earn its place, output by output,
        in a blocked cross-validation (:meth:`_validate`) against a parametric-only fallback
        (σ_z at its floor, σ_w and σ_v as PR learns them; SGP → PR for that output) and, with
        ``guard.release_capped``, against the hyperparameters with the capped inputs released.
        """
        self._runs = []  # each L-BFGS-B run: whether its iteration cap stopped it (ml2_runs_)
        idx = self._hyper_subset(len(Us), rng)
        hp0, resid = self._initial(Us[idx], Y[idx], Fs[idx])
        sizes = [0 if k is None else k.n_params for k in self.kernels]
        bounds = self._bounds(hp0, resid)
        lo, hi = [b[0] for b in bounds], [b[1] for b in bounds]
        has_gp = any(k is not None for k in self.kernels)
        n_extra = self.restarts + (self.guard.restarts if has_gp else 0)
        x0 = np.clip(hp0.pack(), lo, hi)
        starts = self._starts(x0, bounds, resid, rng, n_extra if has_gp else 0)
        if start is not None:
            bounds = self._pin_fixed(bounds, start.pack())
            lo, hi = [b[0] for b in bounds], [b[1] for b in bounds]
            starts = [np.clip(start.pack(), lo, hi)]
        self.n_starts_ = len(starts)
        data = Us[idx], Y[idx], Fs[idx]
        stage = "hyperparameter starts (ML-II)"
        if self._screens(len(starts), len(idx)):
            results = []
            for s in self._screen(starts, bounds, sizes, resid, data):
                results = self._run_starts([s], bounds, sizes, resid, data, stage)
                if results[0]:
                    break
        else:
            results = self._run_starts(starts, bounds, sizes, resid, data, stage)
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

            def refit(start, bounds):  # ML-II from one start (a candidate derived from x)
                return self._optimise(start, bounds, sizes, resid, *data, self.maxiter)

            if self.guard.max_lengthscale and self.guard.release_capped:
                released = self._release(x, bounds, refit)
                if released is not None:
                    options["released"] = released
            if self.guard.max_lengthscale and self.guard.extend_capped:
                extended = self._extend(x, sizes, data)
                if extended is not None:
                    options["extended"] = extended
            options[PARAMETRIC] = self._parametric_only(x0, resid, bounds, data)
            joint_cut = None
            if self.guard.two_stage:  # judged against the others' choice (GuardCandidates._choose)
                self._two_stage_hp = self._two_stage(options[PARAMETRIC], Us, Y, Fs)
                joint = {k: v for k, v in options.items() if k != PARAMETRIC}
                options = {**joint, TWO_STAGE: options[PARAMETRIC]}
                options[PARAMETRIC] = options[TWO_STAGE]  # in the joint posterior both are PR rows
                if self.guard.joint_region:  # learnt only where the cut two stages lose
                    joint_cut = functools.partial(self._joint_cut, x, bounds, refit)
            blocks = np.array_split(idx, folds)  # contiguous in time order
            x = self._validate(options, blocks, Us, Y, Fs, sizes, bounds, resid, joint_cut)
            if self.guard.two_stage:
                self.stages_ = Stages(self.selection_, *self._two_stage_hp)
        return Hyperparameters.unpack(x, sizes)

    # ------------------------------------------------------------------ predict
    @single_threaded
    @flushed()
    def predict(self, U, F, variance: bool = True) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
        """Posterior mean (Nq, n), latent variance (Nq, n) and parametric part f ŵ (Nq, n).

        The observation's predictive variance adds ``noise_var_`` (n,) to the latent one. Without
        ``variance`` the variance is None (the mean alone: O(Nq N) instead of O(Nq N²) exact).
        """
        U, F = np.asarray(U, float), np.asarray(F, float)
        if not self.use_features:
            F = F[:, :, :0]
        Us, Fs = self._scale(U, F)
        mean, var, par = self.posterior_.predict(Us, Fs, variance)
        if self.pr_posterior_ is None:
            return mean, var, par
        m_pr, v_pr, p_pr = self.pr_posterior_.predict(Us, Fs, variance)
        res = self.residual_.predict(U, F, variance) if self.residual_ is not None else None
        for j, mode in enumerate(self._modes()):
            if mode == "joint":
                continue
            mean[:, j], par[:, j] = m_pr[:, j], p_pr[:, j]
            if variance:
                var[:, j] = v_pr[:, j]
            if mode == TWO_STAGE:  # the two stages (PRGP): means add, the band _two_stage_w_variance
                mean[:, j] += res[0][:, j]
                if variance:
                    var[:, j] = res[1][:, j] + self._two_stage_w_variance(U, F, Fs, v_pr, res[1], j)
        return mean, var, par

    def _two_stage_w_variance(self, U, F, Fs, v_pr, gp_var, j) -> np.ndarray:
        """(Nq,) W's variance in a TWO_STAGE output j's band: from what both stages leave
        (``v_pr``, :meth:`_fit_stages`) on the data of the GP on PR's residual, PR's own far from
        it, weighted by λ = the GP's posterior variance ``gp_var`` over its prior variance (0 on
        its data, 1 far from it, in its length-scales). The GP takes up the correlation of PR's
        residual, and so the bias it puts in W, only where it has data; beyond them it reverts to
        its prior mean and the two stages predict, and err, as PR. Issue #14's arm, 1,000
        samples, seed 11: a test whose qd3 spans ±2.6 rad/s against ±1.2 in training; on its
        504 samples farthest from training (≥ 1 std in (q3, qd3)) the two stages erred as PR
        (RMS 0.086 N·m) with a band of std 0.019 (PR's 0.081), covering joint 3 0.65 overall
        (PR 0.95); with λ, 0.99."""
        own = self.pr_w_cov_robust_
        if own is None:
            return v_pr[:, j]
        blk = self.residual_.posterior_.blocks[j]
        prior = blk.kernel.diag(self.residual_._scale(U, F[:, :, :0])[0], blk.theta)
        far = np.clip(gp_var[:, j] / np.maximum(prior, np.finfo(float).tiny), 0.0, 1.0)
        return (1.0 - far) * v_pr[:, j] + far * w_variance(self.pr_posterior_.M_chol, own, Fs[:, j])

    @property
    def noise_var_(self) -> np.ndarray:
        """(n,) σ_v² of the model that predicts each output."""
        out = self.posterior_.noise_var.copy()
        for j, mode in enumerate(self._modes()):
            if mode == PARAMETRIC:
                out[j] = self.pr_posterior_.noise_var[j]
            elif mode == TWO_STAGE:
                out[j] = self.residual_.noise_var_[j]
        return out


def with_region_off(hp: Hyperparameters, kernels) -> Hyperparameters:
    """``hp`` for ``kernels``: an output whose kernel is a :class:`Region` but whose parameters are
    the inner kernel's only (a model saved before Region kernels existed, or, for the joint GPs,
    with the default guard before the joint cut was on by default) gets the onset off."""
    theta = []
    for t, k in zip(hp.theta, kernels, strict=True):
        if isinstance(k, Region) and t.size == k.n_params - 3:
            t = np.concatenate([[REGION_OFF, np.log(REGION_WIDTH), 0.0], t])
        theta.append(np.asarray(t, float))
    return Hyperparameters(hp.log_sigma_w, hp.log_sigma_v, tuple(theta))
