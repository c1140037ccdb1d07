"""ML-II's starts, bounds and priors and their optimisation (thesis §3.3.4): the heuristic initial
values, the bounds in log space, one L-BFGS-B run per start, and the screening of the starts on a
few samples.

:class:`MLStarts` is a mixin of :class:`~diegocal.sgp.estimator.SemiParametricGP` (it uses the
estimator's ``kernels``, ``jobs``, ``maxiter``, ``screen_starts``, ``_slots``, ``_prior`` and
``_say``).
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import minimize

from diegocal.errors import NumericalError
from diegocal.parallel import thread_map
from diegocal.sgp.gp import Hyperparameters, negative_log_likelihood
from diegocal.sgp.guard_options import FTOL
from diegocal.sgp.kernels import REGION_OFF, REGION_WIDTH, is_amplitude, is_fixed, is_lengthscale
from diegocal.sgp.nested import evenly

# ML-II's starts are screened where the hyperparameter subset holds more than 2·SCREEN_SAMPLES
# samples (SemiParametricGP._screen): each start runs on SCREEN_SAMPLES of them evenly spaced in
# time, and only the best one's optimum is refined on all of them.
SCREEN_SAMPLES = 250
LOG_BOUND = 12.0  # |log| of any hyperparameter relative to its scale
# A Region kernel's ratio r (the amplitude above its onset over the one below) lies in these.
REGION_RATIO_BOUND = (1e-3, 1e3)


class MLStarts:
    """The ML-II starts of the SGP estimator, their bounds and priors, and their optimisation."""

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
                elif name.endswith("region_onset"):
                    t[i] = REGION_OFF
                elif name.endswith("log_region_width"):
                    t[i] = np.log(REGION_WIDTH)
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
            for i, name in enumerate(k.names):
                if is_lengthscale(name):
                    lo.append(np.log(1e-2))
                    hi.append(np.log(g.max_lengthscale) if g.max_lengthscale else np.log(1e3))
                elif is_fixed(name):  # held at the start (_learn: at a given start's)
                    lo.append(hp0.theta[j][i])
                    hi.append(hp0.theta[j][i])
                elif name.endswith("log_region_ratio"):
                    lo.append(np.log(REGION_RATIO_BOUND[0]))
                    hi.append(np.log(REGION_RATIO_BOUND[1]))
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

    def _pin_fixed(self, bounds, vec) -> list:
        """``bounds`` with the fixed parameters (:func:`is_fixed`, a Region's onset and width) at
        ``vec``'s values."""
        out = list(bounds)
        for _, k, names in self._slots():
            for i, name in enumerate(names):
                if is_fixed(name):
                    out[k + i] = (vec[k + i], vec[k + i])
        return out

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
        self._ran(res)
        ok = np.isfinite(res.fun) and res.fun < 1e24
        return (float(res.fun), res.x) if ok else None

    def _ran(self, res) -> None:
        """Count an L-BFGS-B run of this fit, and whether its iteration cap stopped it before its
        tolerance (:attr:`ml2_runs_`; list.append is atomic: runs in threads)."""
        self._runs.append(bool(res.status == 1))

    def _ran_in(self, other) -> None:
        """Count the runs of another estimator's fit (a residual GP's) as this fit's."""
        self._runs.extend(other._runs)

    @property
    def ml2_runs_(self) -> tuple[int, int]:
        """(L-BFGS-B runs of the last fit, those its iteration cap stopped before its tolerance: a
        start cut short might have ended better than the one kept; none when hyperparameters were
        given, a restored fit)."""
        runs = getattr(self, "_runs", ())
        return len(runs), int(sum(runs))

    def _run_starts(self, starts, bounds, sizes, resid, data, stage: str) -> list:
        """``_optimise`` from each of ``starts`` on ``data``, in ``jobs`` threads (LAPACK drops the
        GIL), in order; ``stage`` names them on the progress bar."""
        done = []

        def run(s):
            out = self._optimise(s, bounds, sizes, resid, *data, self.maxiter)
            done.append(1)  # list.append is atomic: a count across threads
            self._say(stage, len(done), len(starts))
            return out

        self._say(stage, 0, len(starts))
        return thread_map(run, starts, self.jobs)

    def _screens(self, n_starts: int, n_samples: int) -> bool:
        """Whether ML-II's ``n_starts`` starts on ``n_samples`` samples are screened (:meth:`_screen`):
        with ``screen_starts``, more than one start and more than 2·SCREEN_SAMPLES samples."""
        return self.screen_starts and n_starts > 1 and n_samples > 2 * SCREEN_SAMPLES

    def _screen(self, starts, bounds, sizes, resid, data) -> list:
        """``starts`` in the order to refine them: the optima of their ML-II on SCREEN_SAMPLES of
        ``data``'s samples evenly spaced in time, best first, then the starts whose screening
        failed (:meth:`_learn` refines the first, and the next only where a refinement fails).

        Why: a likelihood on 1,000 samples costs some 40× one on 250, and the starts mostly pick
        the basin, not the point in it. On the scale bench's arm (20,000 samples) the three
        starts of the joint GPs ended within 3.5 nats of each other, and those of each GP on PR's
        residual within 0.2, each run 25-40 likelihoods of 1,000 samples: 3 full runs per fit
        and 9 on the residual. Not always the same basin: on issue #14's case PRGP's screened
        start refined to a likelihood 7 nats below the best full start's (joint 3 0.0046 against
        0.0041), and on the reaction wheel PRGP's screened starts did better than the full ones."""
        few = evenly(np.arange(len(data[0])), SCREEN_SAMPLES)
        small = tuple(a[few] for a in data)
        stage = f"hyperparameter starts screened on {len(few)} samples"
        results = self._run_starts(starts, bounds, sizes, resid, small, stage)
        found = sorted((r[0], i) for i, r in enumerate(results) if r)  # ties: the earlier start
        failed = [s for s, r in zip(starts, results, strict=True) if not r]
        return [results[i][1] for _, i in found] + failed
