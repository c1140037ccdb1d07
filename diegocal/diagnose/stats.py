"""Statistics of the diagnosis: tests whose false-alarm rate is known on time-correlated residuals.

Samples 10 ms apart are not independent. Every variance here is a *block* (cluster-robust)
variance: the residuals are cut into sub-blocks longer than their correlation time
(:func:`cluster_length`), and sums over a sub-block are treated as independent. Three tests:

- :func:`out_of_sample_test`: does a correction fitted on the training blocks predict the
  residual of the validation blocks? The residual is regressed on the correction through the
  origin; the slope's cluster-robust t (Student t with clusters − 1 degrees of freedom) tests it.
  Under "nothing to find" the correction is independent of the validation noise and the slope is
  0; the standard error is estimated from the residual *after* the correction, so a strong effect
  confined to a few sub-blocks (friction in part of a joint's range) is not hidden by its own
  unevenness, as it would be by a t-test of per-block MSE differences.
- :func:`binned_means`: the residual's mean per quantile bin of a state variable with block bands.
- :func:`change_point`: CUSUM of the residual in time against the Kolmogorov distribution of a
  Brownian bridge's maximum, with the block (long-run) variance.

Multiple tests are corrected by Bonferroni (:func:`critical_t`): the family-wise false-alarm rate
over every candidate and channel of a log is at most ``alpha``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import stats

from diegocal.evaluate import sub_blocks

#: Sub-blocks are at least this many samples, and this many correlation times, long.
MIN_CLUSTER = 10
CORRELATION_TIMES = 5.0
#: Every contiguous run of validation samples gives at least this many sub-blocks.
MIN_RUN_PIECES = 3


def autocorrelation_time(r: np.ndarray, max_lag: int = 200) -> float:
    """Integrated autocorrelation time (samples) of a residual (T,) or (T, d), NaN-tolerant.

    τ = 1 + 2 Σ_k ρ_k summed until the first non-positive ρ_k (Geyer's initial positive sequence,
    simplified); 1 for white noise. Missing samples (NaN) are set to the mean, which only shortens
    the estimate slightly.
    """
    r = np.asarray(r, float)
    r = r.reshape(r.shape[0], -1)
    taus = []
    for col in r.T:
        ok = np.isfinite(col)
        if ok.sum() < 20:
            continue
        x = np.where(ok, col - col[ok].mean(), 0.0)
        n = x.size
        f = np.fft.rfft(x, 2 * n)
        acf = np.fft.irfft(f * np.conj(f))[: min(max_lag, n - 1) + 1]
        if acf[0] <= 0:
            continue
        rho = acf / acf[0]
        tau = 1.0
        for k in range(1, rho.size):
            if rho[k] <= 0:
                break
            tau += 2.0 * rho[k]
        taus.append(tau)
    return float(np.median(taus)) if taus else 1.0


def cluster_length(residuals, min_samples: int = MIN_CLUSTER) -> int:
    """Sub-block length (samples) for block variances: ``CORRELATION_TIMES`` correlation times of
    the residuals (median over channels), at least ``min_samples``."""
    taus = [autocorrelation_time(r) for r in residuals]
    tau = float(np.median(taus)) if taus else 1.0
    return int(max(min_samples, np.ceil(CORRELATION_TIMES * tau)))


def critical_t(alpha: float, n_tests: int, df: int) -> float:
    """One-sided Student-t critical value at level ``alpha / n_tests`` (Bonferroni)."""
    return float(stats.t.isf(alpha / max(n_tests, 1), max(df, 1)))


@dataclass(frozen=True)
class OutOfSample:
    """Result of :func:`out_of_sample_test`.

    slope : regression of the validation residual on the correction (1 = the correction is right)
    t, df, p : its cluster-robust t, degrees of freedom (clusters − 1), one-sided p-value
    sse_before, sse_after : Σ r², Σ (r − a)² over the validation rows (weighted units)
    se : the slope's cluster-robust standard error (inf where there is no test): an effect k times
        the correction is found when k / se passes the threshold (:mod:`.limits`)
    length : the sub-block length (samples) the variance was taken over
    removed : Σ r² − Σ (r − a)² per validation sample (the mask's samples in time order, not all
        T: every tested candidate keeps it), to compare candidates on a common partition
        (:func:`paired_difference`): what one candidate removes beyond another is the difference of
        their ``removed`` whether or not they act on the same channels (the channels only one acts
        on keep their error under the other)
    """

    slope: float
    t: float
    df: int
    p: float
    sse_before: float
    sse_after: float
    length: int
    removed: np.ndarray
    se: float = float("inf")

    @property
    def gain(self) -> float:
        """Fraction of the validation error the correction removes (may be negative)."""
        return 1.0 - self.sse_after / self.sse_before if self.sse_before > 0 else 0.0


def out_of_sample_test(
    r: np.ndarray, a: np.ndarray, samples: np.ndarray, mask: np.ndarray, clusters: np.ndarray | None = None
) -> OutOfSample:
    """Test whether a correction ``a`` predicts the residual ``r`` on held-back rows.

    Parameters
    ----------
    r, a : (N,) residual and correction on the validation rows (already weighted)
    samples : (N,) int, the sample of each row (several rows may share one: a marker's 3 axes,
        or several channels)
    mask : (T,) bool, the validation samples (sub-blocks never span a gap in it)

    The sub-blocks are ``CORRELATION_TIMES`` correlation times of the residual *after* the
    correction (at least MIN_CLUSTER samples): that residual is the noise when the correction is
    right, and a correction that explains only part of the structure gets longer sub-blocks, so
    fewer degrees of freedom, which errs on the side of no finding. Where no run of validation
    samples is long enough for MIN_RUN_PIECES sub-blocks of MIN_CLUSTER (a static-pose log: one
    sample per pose, validation runs of a few poses) the floor is what the longest run allows
    (:func:`_floor`); otherwise those runs would give fewer than three sub-blocks and no test at
    all, whatever the error.

    ``clusters``: (N,) labels of the independent units, given where the residual's own correlation
    time does not say what is independent (an open-loop prediction restarted every 2 s carries its
    error through each window: the windows are the units).
    """

    r, a = np.asarray(r, float), np.asarray(a, float)
    samples, mask = np.asarray(samples, int), np.asarray(mask, bool)
    T = mask.size
    before = np.bincount(samples, weights=r * r, minlength=T)
    after = np.bincount(samples, weights=(r - a) ** 2, minlength=T)
    sse_before, sse_after = float(before.sum()), float(after.sum())
    removed = (before - after)[mask]  # kept by every tested candidate: the mask's samples only
    saa = float(a @ a)
    floor = _floor(mask)
    if r.size < 3 * floor or saa <= 0 or not np.isfinite(saa):
        return OutOfSample(0.0, 0.0, 1, 1.0, sse_before, sse_after, floor, removed)
    slope = float(a @ r) / saa
    u = r - slope * a
    seen = np.zeros(T, bool)
    seen[samples] = True
    if clusters is None:
        u_by_sample = np.bincount(samples, weights=u, minlength=T)[seen]
        tau = autocorrelation_time(u_by_sample)
        length = int(max(floor, min(np.ceil(CORRELATION_TIMES * tau), _longest_sub_block(mask & seen))))
        _, cl = np.unique(sub_blocks(mask & seen, length)[samples], return_inverse=True)
    else:
        _, cl = np.unique(np.asarray(clusters), return_inverse=True)
        length = int(round(int(seen.sum()) / (int(cl.max()) + 1)))
    C = int(cl.max()) + 1
    if C < 3:
        return OutOfSample(
            slope, 0.0, max(C - 1, 1), 1.0, sse_before, sse_after, length, removed
        )
    s = np.bincount(cl, weights=a * u, minlength=C)
    var = float(s @ s) / saa**2 * C / (C - 1)
    se = np.sqrt(var) if var > 0 else np.inf
    t = slope / se if np.isfinite(se) else 0.0
    df = C - 1
    return OutOfSample(
        slope, float(t), df, float(stats.t.sf(t, df)), sse_before, sse_after, length, removed, float(se)
    )


def _longest_sub_block(mask: np.ndarray) -> int:
    """The longest sub-block that still cuts every run of ``mask`` into MIN_RUN_PIECES pieces.

    A residual that holds a second, not yet modelled effect has a long correlation time; without
    this cap its sub-blocks would outgrow the validation blocks, leave one or two degrees of
    freedom, and hide a strong effect behind a weaker one (two effects on one joint). Once the
    stronger effect is in the model, the next round tests the other on a residual near noise.
    """
    runs = _runs(mask)
    if runs.size == 0:
        return MIN_CLUSTER
    return max(_floor(mask), int(runs.min()) // MIN_RUN_PIECES)


def _runs(mask: np.ndarray) -> np.ndarray:
    """Lengths (samples) of the runs of True in ``mask``."""
    idx = np.flatnonzero(mask)
    starts = np.concatenate([[0], np.flatnonzero(np.diff(idx) > 1) + 1, [idx.size]])
    return np.diff(starts) if idx.size else np.zeros(0, int)


def _floor(mask: np.ndarray) -> int:
    """The shortest sub-block: MIN_CLUSTER samples, or where no run of ``mask`` holds
    MIN_RUN_PIECES of them, what the longest run does hold (at least 1). Only a log whose every
    run is that short gets less: a static-pose log, whose samples are poses the robot moved
    between, not a time series sampled faster than its correlation time."""
    runs = _runs(mask)
    longest = int(runs.max()) if runs.size else 0
    return int(min(MIN_CLUSTER, max(1, longest // MIN_RUN_PIECES)))


def paired_difference(x: np.ndarray, y: np.ndarray, mask: np.ndarray, length: int) -> tuple[float, float, int]:
    """Mean and standard error over sub-blocks of ``mask`` (T,) of the per-block sums of ``x − y``
    (values on the mask's samples, in time order: :class:`OutOfSample`'s ``removed``); and the
    number of sub-blocks. The sub-blocks are ``length`` samples, or CORRELATION_TIMES correlation
    times of ``x − y`` where that is longer (up to the longest a run of the mask allows): two
    corrections differ by a function of the state, which moves slower than either's residual."""
    mask = np.asarray(mask, bool)
    d = np.asarray(x, float) - np.asarray(y, float)
    own = np.ceil(CORRELATION_TIMES * autocorrelation_time(d))
    length = int(max(length, min(own, _longest_sub_block(mask))))
    sums = np.bincount(sub_blocks(mask, length)[mask], weights=d)
    if sums.size < 3:
        return float(sums.mean()) if sums.size else 0.0, float("inf"), int(sums.size)
    return float(sums.mean()), float(sums.std(ddof=1) / np.sqrt(sums.size)), int(sums.size)


@dataclass(frozen=True)
class BinnedMeans:
    """The residual's mean per bin of a variable, with block standard errors.

    edges : (B + 1,) bin edges in the variable's unit; centre : (B,) median of the variable per bin;
    mean, se : (B,) mean residual and its block standard error; count : (B,) samples
    """

    variable: str
    edges: np.ndarray
    centre: np.ndarray
    mean: np.ndarray
    se: np.ndarray
    count: np.ndarray

    def to_dict(self) -> dict:
        def clean(x):
            return [None if not np.isfinite(v) else float(v) for v in np.asarray(x, float)]

        return {
            "variable": self.variable,
            "edges": clean(self.edges),
            "centre": clean(self.centre),
            "mean": clean(self.mean),
            "se": clean(self.se),
            "count": [int(c) for c in self.count],
        }


def quantile_edges(x: np.ndarray, n_bins: int) -> np.ndarray:
    """Bin edges at quantiles of the finite values of ``x``; repeated edges merged (a sign
    variable gets 2 bins)."""
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    if x.size == 0:
        return np.array([0.0, 1.0])
    edges = np.unique(np.quantile(x, np.linspace(0, 1, n_bins + 1)))
    if edges.size < 2:
        edges = np.array([edges[0] - 0.5, edges[0] + 0.5])
    vals = np.unique(x)
    if vals.size <= n_bins:  # a discrete variable (a sign): one bin per value
        mid = 0.5 * (vals[1:] + vals[:-1])
        edges = np.concatenate([[vals[0] - 0.5], mid, [vals[-1] + 0.5]]) if vals.size > 1 else edges
    return edges


def bin_index(x: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """The bin (0..B-1) of each value; -1 for NaN. Values outside the edges go to the end bins."""
    idx = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, edges.size - 2)
    return np.where(np.isfinite(x), idx, -1)


def binned_means(
    r: np.ndarray, x: np.ndarray, clusters: np.ndarray, edges: np.ndarray, variable: str = ""
) -> BinnedMeans:
    """Mean of the residual ``r`` (N,) per bin of ``x`` (N,), block SEs from ``clusters`` (N,)."""
    r, x = np.asarray(r, float), np.asarray(x, float)
    ok = np.isfinite(r) & np.isfinite(x) & (clusters >= 0)
    r, x, cl = r[ok], x[ok], clusters[ok]
    b = bin_index(x, edges)
    B = edges.size - 1
    count = np.bincount(b, minlength=B)
    total = np.bincount(b, weights=r, minlength=B)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = total / count
    centre = np.array([np.median(x[b == k]) if count[k] else np.nan for k in range(B)])
    se = np.full(B, np.nan)
    for k in range(B):
        sel = b == k
        if count[k] < 2:
            continue
        _, c = np.unique(cl[sel], return_inverse=True)
        s = np.bincount(c, weights=r[sel] - mean[k])
        n_c = s.size
        if n_c >= 2:
            se[k] = np.sqrt(float(s @ s) * n_c / (n_c - 1)) / count[k]
    return BinnedMeans(variable, edges, centre, mean, se, count)


@dataclass(frozen=True)
class ChangePoint:
    """CUSUM change-point test: statistic, p-value, and where the largest departure is (sample)."""

    statistic: float
    p: float
    at: int


def change_point(r: np.ndarray, clusters: np.ndarray) -> ChangePoint:
    """max_k |Σ_{t<=k} (r_t − r̄)| / (σ_lr √N) against the Kolmogorov distribution.

    ``r`` (N,) in time order (NaN skipped), ``clusters`` its sub-blocks; σ_lr² (the long-run
    variance) = Σ_c (Σ_{t∈c} (r_t − r̄))² / N.
    """
    r = np.asarray(r, float)
    ok = np.isfinite(r) & (clusters >= 0)
    idx = np.flatnonzero(ok)
    if idx.size < 20:
        return ChangePoint(0.0, 1.0, 0)
    x = r[ok] - r[ok].mean()
    _, c = np.unique(clusters[ok], return_inverse=True)
    s = np.bincount(c, weights=x)
    lrv = float(s @ s) / x.size
    if lrv <= 0:
        return ChangePoint(0.0, 1.0, 0)
    cusum = np.cumsum(x)
    k = int(np.argmax(np.abs(cusum)))
    stat = float(np.abs(cusum[k]) / np.sqrt(lrv * x.size))
    return ChangePoint(stat, float(stats.kstwobign.sf(stat)), int(idx[k]))
