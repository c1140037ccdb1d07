"""The region scan: where a two-stage GP on PR's residual should be cut at an onset in its
joint's angle (:class:`~diegocal.sgp.kernels.Region`; issue #14, rounds 5-8), and the joint GP
cut at the same onset (Guard.joint_region).

:class:`RegionScan` is a mixin of :class:`~diegocal.sgp.guard.GuardCandidates` (it uses the
estimator's ``kernels``, ``_slots``, ``_pin_fixed``, ``_residual_estimator``, ``_learn_residual``
and ``_two_stage_hp``).
"""

from __future__ import annotations

import numpy as np

from diegocal.errors import FitError, NumericalError
from diegocal.sgp.gp import Hyperparameters, negative_log_likelihood
from diegocal.sgp.kernels import REGION_WIDTH, Region, cut_outputs, is_amplitude
from diegocal.sgp.nested import evenly

# The region scan of the two-stage GPs (RegionScan._region_scan): onsets at these quantiles
# of the joint's training angles (then placed between two of them, _place_onset), amplitudes
# below and above the onset at these multiples of the uncut GP's σ_z, the likelihood on at most
# REGION_SCAN_MAX samples evenly spaced in time; an output is cut where the best onset raises
# that likelihood by more than REGION_MIN_NATS.
REGION_QUANTILES = np.linspace(0.025, 0.975, 39)
REGION_AMPLITUDES = (0.1, 0.3, 1.0, 3.0)
REGION_SCAN_MAX = 400
REGION_MIN_NATS = 10.0
REGION_PLACE_MAX = 24  # onsets tried first when placing one between two training angles


class RegionScan:
    """Onsets for the two-stage GPs (:meth:`_region_scan`) and the joint cut (:meth:`_joint_cut`)."""

    def _region_scan(self, hp_res: Hyperparameters, U, res, F) -> Hyperparameters:
        """The two-stage GPs cut at an onset in their joint's angle where the likelihood asks for
        it (:class:`~diegocal.sgp.kernels.Region`; ``region_inputs``). Per output: the uncut GP's
        likelihood against a scan of onsets (REGION_QUANTILES of the angle) and amplitudes on
        each side (REGION_AMPLITUDES × the uncut σ_z) on REGION_SCAN_MAX samples evenly spaced in
        time; the best onset is then placed between two consecutive training angles
        (:meth:`_place_onset`). Where the cut beats the uncut GP by more than REGION_MIN_NATS, the
        output's GP is re-learnt by ML-II from it, the onset held, and the onset placed again
        with the new hyperparameters. The cross-validation then judges the two stages as before.

        Why: the 3-link arm's hidden friction on joint 3 acts above 1.78 rad only; an uncut SE GP
        on PR's residual carries the step some 0.3 rad below the onset, where it doubles PR's error
        and covers the residual within ±2σ at 0.05 (bench_sgp_onset)."""
        est = self._residual_estimator()
        cut = [j for j, k in enumerate(est.kernels) if isinstance(k, Region)]
        if not cut:
            return hp_res
        _, _, _, Us, _ = est._standardise(U, res, F)
        spaced = evenly(np.arange(len(Us)), REGION_SCAN_MAX)
        starts = {}
        for j in cut:
            kernel, base = est.kernels[j], hp_res.theta[j]
            likelihood = _OutputLikelihood(kernel, Us, res[:, j], hp_res.log_sigma_v[j], spaced)
            amp = [i for i, name in enumerate(kernel.names) if is_amplitude(name)][0]

            def cut_at(c, below, above, base=base, amp=amp):
                theta = base.copy()
                theta[:3] = c, np.log(REGION_WIDTH), np.log(above / below)
                theta[amp] = base[amp] + np.log(below)
                return theta

            grid = np.quantile(Us[:, kernel.dim], REGION_QUANTILES)
            scores = likelihood.hard_cuts(base[3:], grid, REGION_AMPLITUDES)
            i, below, above = np.unravel_index(int(np.argmin(scores)), scores.shape)
            pair = REGION_AMPLITUDES[below], REGION_AMPLITUDES[above]
            bracket = grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)]
            theta, gain = self._place_onset(likelihood, cut_at(grid[i], *pair), base, bracket)
            if gain > REGION_MIN_NATS:
                starts[j] = (theta, bracket, likelihood)
        if not starts:
            return hp_res
        theta = tuple(starts[j][0] if j in starts else np.zeros(0) for j in range(len(self.kernels)))
        try:
            start = Hyperparameters(hp_res.log_sigma_w, hp_res.log_sigma_v, theta)
            hp = self._learn_residual(U, res, F, sorted(starts), start)
        except (NumericalError, FitError):
            return hp_res
        log_sigma_v, out = hp_res.log_sigma_v.copy(), list(hp_res.theta)
        for j, (_, bracket, likelihood) in starts.items():
            likelihood.log_sigma_v = hp.log_sigma_v[j]
            out[j] = self._place_onset(likelihood, hp.theta[j], hp_res.theta[j], bracket)[0]
            log_sigma_v[j] = hp.log_sigma_v[j]
        return Hyperparameters(hp_res.log_sigma_w, log_sigma_v, tuple(out))

    def _cut_outputs(self) -> list:
        """The outputs whose two-stage GP is cut at an onset (:meth:`_region_scan`)."""
        return cut_outputs(self._residual_estimator().kernels, self._two_stage_hp[1].theta)

    @staticmethod
    def _place_onset(likelihood, theta, uncut, bracket) -> tuple[np.ndarray, float]:
        """(``theta`` with its onset at the midpoint of two consecutive training angles in
        ``bracket`` that maximises the likelihood, the likelihood's gain over ``uncut``).

        Coarse to fine: REGION_PLACE_MAX midpoints evenly among those left are tried, with the
        likelihood on its spaced samples and at most REGION_SCAN_MAX samples in their range, and
        the range narrows to the best one's neighbours until it holds no more midpoints than are
        tried (then every sample in it counts, unless more than REGION_SCAN_MAX share those few
        angles). The gain is the likelihood's on its spaced samples and at most REGION_SCAN_MAX
        samples in the bracket. (Every sample of a bracket, as before, took 1,000 samples per
        likelihood at 20,000 and 16 CPU-s per fit.)"""
        x = likelihood.angles

        def near(lo, hi):  # the likelihood on its samples and ≤ REGION_SCAN_MAX in [lo, hi]
            return likelihood.with_samples(evenly(np.flatnonzero((x >= lo) & (x <= hi)), REGION_SCAN_MAX))

        def at(c):
            t = theta.copy()
            t[0] = c
            return t

        lo, hi = bracket
        v = np.unique(x[(x >= lo) & (x <= hi)])
        mids = (v[1:] + v[:-1]) / 2 if len(v) > 1 else np.array([theta[0]])
        while True:
            local = near(mids[0], mids[-1])
            tried = evenly(mids, REGION_PLACE_MAX)
            k = int(np.argmin([local(at(c)) for c in tried]))
            if len(tried) == len(mids):
                break
            mids = mids[(mids >= tried[max(k - 1, 0)]) & (mids <= tried[min(k + 1, len(tried) - 1)])]
        judge = near(lo, hi)
        return at(tried[k]), judge(uncut) - judge(at(tried[k]))

    def _joint_cut(self, x, bounds, optimise, onsets: dict) -> np.ndarray | None:
        """Guard.joint_region: ``x`` with the joint GP of each output in ``onsets`` (output ->
        its two-stage GP's parameters as the region scan cut them) cut at the same onset, width
        and side ratio, and every other hyperparameter re-optimised from there by
        ``optimise(start, bounds)``, the onsets held; None when no output is cut or the
        optimisation fails. Both estimators standardise the same inputs, so the onset carries
        over as it is."""
        start = x.copy()
        for j, k, _ in self._slots():
            if j in onsets and isinstance(self.kernels[j], Region):
                start[k : k + 3] = onsets[j][:3]
        if np.array_equal(start, x):
            return None
        result = optimise(start, self._pin_fixed(bounds, start))
        return None if result is None else result[1]


class _OutputLikelihood:
    """One output's negative log marginal likelihood (a GP on PR's residual, no features) on a
    subset of the samples, as a function of its kernel's parameters (the region scan's)."""

    def __init__(self, kernel, Us, y, log_sigma_v, samples):
        self.kernel, self.Us, self.y, self.log_sigma_v = kernel, Us, y, log_sigma_v
        self.samples = np.asarray(samples)
        self.angles = Us[:, kernel.dim]

    def with_samples(self, extra) -> _OutputLikelihood:
        """The same likelihood on its samples and ``extra`` (indices)."""
        return _OutputLikelihood(self.kernel, self.Us, self.y, self.log_sigma_v, np.union1d(self.samples, extra))

    def hard_cuts(self, inner, onsets, amplitudes) -> np.ndarray:
        """(onsets, A, A) negative log likelihood of the cut GP at each onset (a hard step: the
        two sides independent), the base kernel ``inner`` scaled by each of ``amplitudes`` (A)
        below and above: each side's k_0 is diagonalised once and every amplitude then costs
        O(n), where the kernel itself (:meth:`__call__`) factorises all A² pairs. The region
        scan's (a start for :meth:`RegionScan._place_onset`, which uses the kernel)."""
        idx = self.samples
        X, y = self.Us[idx], self.y[idx]
        K0 = self.kernel.kernel(X, X, inner)
        noise = np.exp(2.0 * self.log_sigma_v)
        s2 = np.asarray(amplitudes, float)[:, None] ** 2

        def side(mask):
            if not mask.any():
                return np.zeros(len(s2))
            lam, V = np.linalg.eigh(K0[np.ix_(mask, mask)])
            d = s2 * np.maximum(lam, 0.0) + noise  # (A, n_side)
            z2 = (V.T @ y[mask]) ** 2
            return 0.5 * (np.log(d).sum(1) + (z2 / d).sum(1) + mask.sum() * np.log(2 * np.pi))

        # a sample exactly at an onset is above it here and half on each side in the kernel (a =
        # 0.5), and the amplitudes scale all of k_0 where the scan scales its first σ_z: equal
        # for one SE kernel; either way only the scan's start differs, _place_onset uses the kernel
        x = X[:, self.kernel.dim]
        out = np.empty((len(onsets), len(s2), len(s2)))
        for i, c in enumerate(onsets):
            below = x < c
            out[i] = side(below)[:, None] + side(~below)[None, :]
        return out

    def __call__(self, theta) -> float:
        idx = self.samples
        vec = np.concatenate([[0.0, self.log_sigma_v], theta])
        try:
            return negative_log_likelihood(
                vec,
                [self.kernel],
                self.Us[idx],
                self.y[idx, None],
                np.zeros((len(idx), 1, 0)),
                [theta.size],
                grad=False,
            )
        except NumericalError:
            return np.inf
