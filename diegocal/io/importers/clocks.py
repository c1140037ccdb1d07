"""Two files, two clocks: the offset between them, estimated from the motion both record.

A motion capture PC and a robot's logger start their clocks apart; without an offset in the map
the import reads both on one time axis and keeps only their apparent overlap, misaligned. Each
file's *motion envelope* tells when the robot moved: the norm of its channels' rates, each channel
scaled to unit spread so volts, radians and metres weigh alike (a marker gives three channels, its
coordinates). Both are put on one uniform grid and low-passed; for every shift d that leaves at
least a quarter of the shorter file overlapping, Pearson's r on the overlap alone,

.. math:: r(d) = \\operatorname{corr}\\big(s_a(t),\\; s_b(t - d)\\big),

d being what to add to file b's times (its ``time_offset``). Cross-correlation of speed envelopes
is the usual way to align mocap with other recordings (e.g. "time synchronisation by
cross-correlation" in the IMU-to-mocap literature); the speed, unlike the position, does not depend
on where the mocap frame is.

The peak of r is only an estimate when the motion fixes it. A slow, repeating motion correlates
with itself at many shifts, and r over a short overlap is noisy: on 40-s logs of sums of sines, r
reached 0.83 at shifts 20-30 s off over a quarter of the log, against 0.47-0.79 at the true one.
So r is judged against its noise. Fisher's :math:`z = \\operatorname{artanh} r` has standard error
:math:`1/\\sqrt{n_\\text{eff} - 3}`, with :math:`n_\\text{eff} = n / \\tau` the overlap's
independent samples and :math:`\\tau = 1 + 2\\sum_{k \\le L} (1 - \\tfrac{k}{L+1})\\,\\rho_a(k)\\rho_b(k)`
the envelopes' integral time (Bartlett's variance of the cross-correlation of two autocorrelated
series, with Newey and West's taper up to L, a quarter of the shorter file). Shifts are searched
where the overlap holds at least MIN_INDEPENDENT such samples, and the one whose r is surest (the
largest :math:`z / \\text{se}`: r weighed by its overlap) is the candidate, k. It must reach
MIN_CORRELATION, and no other shift m may fit about as well: were m the true offset, k would be the
motion repeating itself, and r at k no more than :math:`r_m \\rho(|k - m|)`, with :math:`\\rho` the
envelopes' own autocorrelation (raised by its standard error); k must lead that by MARGIN standard
errors of the difference of the two z. Shifts that fail this next to k are k's own peak; one apart
from it (a repeat, or too little motion shared) leaves no estimate. The estimate, the top of k's
peak refined by a parabola, has the standard error of a correlation peak's position,
:math:`\\sqrt{(1 - r^2) / (n_\\text{eff}\\, r\\, |r''|)}` (the curvature of the log-likelihood
:math:`-\\tfrac{n_\\text{eff}}{2}\\log(1 - r^2)` at the peak, as in time-delay estimation). The
clocks are said to disagree only beyond MARGIN of it (and AGREE_SAMPLES samples), and
``time_offset: auto`` applies it only when it is within AGREE_SAMPLES samples.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, replace

import numpy as np
from scipy.signal import correlate

from diegocal.errors import LogFormatError
from diegocal.io.importers.mapping import MOCAP_KINDS, MapError
from diegocal.io.importers.signals import lowpass, resample, uniform_grid

log = logging.getLogger(__name__)

#: Streams whose values follow the robot's motion, in the order a file's motion is taken from.
MOTION_STREAMS = ("markers", "q", "qd", "pots")
#: Below this peak correlation the files are not taken to share a motion: no estimate.
MIN_CORRELATION = 0.5
#: Least overlap a candidate shift must leave, as a fraction of the shorter file.
MIN_OVERLAP = 0.25
#: ... and in independent samples of the motion (overlap / integral time): r over fewer is too noisy
#: to tell one shift from another (on 40-s logs of slow sums of sines, 20 samples are about 20 s).
MIN_INDEPENDENT = 20.0
#: How many standard errors (of the difference of Fisher's z) the candidate shift must lead every other
#: by (allowing for the motion's repeats); and how far from 0, in its own standard errors, an
#: estimate must be to warn.
MARGIN = 2.0
#: Clocks within this many samples of the slower file agree (no warning); ``time_offset: auto`` needs
#: its estimate this well known (its standard error).
AGREE_SAMPLES = 2
#: The speed envelope keeps what moves slower than this (Hz): the robot's motion, not sensor noise.
ENVELOPE_HZ = 5.0
#: Finest grid the correlation is computed on (Hz): the envelopes hold nothing above ENVELOPE_HZ, and
#: the parabola through the peak resolves a fraction of a step.
MAX_GRID_HZ = 250.0
#: A marker coordinate is scaled by its own rate's spread, but by at least this share of the largest
#: (a marker that hardly moves would add its noise at full weight).
MARKER_SPREAD_FLOOR = 0.1


@dataclass(frozen=True)
class OffsetEstimate:
    """The clock offset of ``other`` against ``reference`` from the motion both record.

    offset_s: to add to ``other``'s times to match ``reference``'s (s), None where the motion does
    not fix it (``why`` says why, in words); se_s: its standard error (s); r: the correlation of
    the envelopes at the best shift ``best_s`` (s), the top of the surest correlation's peak;
    rival_s, rival_r: a shift apart from that peak that fits about as well, and its r (None where
    none does); overlap_s: the overlap the best shift leaves (s).
    """

    reference: str
    other: str
    offset_s: float | None
    r: float
    signals: str  # "marker speed vs joint speed", for messages
    se_s: float = float("nan")
    best_s: float = float("nan")
    rival_s: float | None = None
    rival_r: float | None = None
    overlap_s: float = 0.0
    why: str = ""

    @property
    def fixed(self) -> bool:
        """Whether the motion fixes the offset."""
        return self.offset_s is not None


def align_sources(series: list, sources: dict, clock_source: str | None, notes: list[str]):
    """Estimate each file's offset against the reference file (the clock's source, else the mocap
    file, else the first), apply it where the map says ``time_offset: auto``, warn where the files
    disagree by more than AGREE_SAMPLES samples and MARGIN standard errors. Returns (series, the
    estimates the motion fixes)."""
    motion = {}
    for s in sorted((s for s in series if s.stream in MOTION_STREAMS), key=lambda s: MOTION_STREAMS.index(s.stream)):
        motion.setdefault(s.source, s)
    if len(motion) < 2:
        return series, []
    mocap = [n for n in motion if sources[n].kind in MOCAP_KINDS]
    ref = clock_source if clock_source in motion else (mocap or list(motion))[0]
    estimates = []
    for name, s in motion.items():
        if name == ref:
            continue
        rate = grid_rate(motion[ref].time, s.time)
        ref_env = motion_envelope(motion[ref].stream, motion[ref].time, motion[ref].data, rate)
        spec, other = sources[name].spec, motion_envelope(s.stream, s.time, s.data, rate)
        what = (f"{_words(motion[ref].stream)} in {sources[ref].path.name} vs {_words(s.stream)} in "
                f"{sources[name].path.name}")
        est = None if ref_env is None or other is None else estimate_offset(ref_env, other, (ref, name), what)
        period = max(float(np.median(np.diff(x.time))) for x in (motion[ref], s))
        if spec.auto_offset:
            offset = _auto(est, name, sources[ref].path.name, what, period)
            series = [replace(x, time=x.time + offset) if x.source == name else x for x in series]
            notes.append(f"time_offset: auto for {name}: {est.offset_s:+.6g} s ± {est.se_s:.2g} s "
                         f"({what}, r = {est.r:.2f})")
        elif est is not None and est.fixed and not np.isfinite(est.se_s):  # a peak at the end of the shifts
            notes.append(f"clocks of {name} and {ref} not checked: the motion's best shift, {est.offset_s:+.4g} s, "
                         f"lies at the end of those searched ({what}); the stated clocks kept")
        elif est is not None and est.fixed and abs(est.offset_s) <= max(AGREE_SAMPLES * period, MARGIN * est.se_s):
            notes.append(f"clocks of {name} and {ref} agree as far as the motion tells: {est.offset_s:+.4g} s ± "
                         f"{est.se_s:.2g} s ({what}, r = {est.r:.2f})")
        elif est is not None and est.fixed:
            log.warning("%s and %s: their clocks disagree by %+.4g s ± %.2g s (%s, r = %.2f); set "
                        "`time_offset: %.6g` for source %r in the map, or `time_offset: auto`",
                        sources[name].path.name, sources[ref].path.name, est.offset_s, est.se_s, what, est.r,
                        spec.time_offset + est.offset_s, name)
        elif est is not None and not est.fixed:  # said: the user must know the clocks were not checked
            notes.append(f"clocks of {name} and {ref} not checked: {est.why}; the stated clocks kept")
        if est is not None and est.fixed and np.isfinite(est.se_s):
            estimates.append(est)
    return series, estimates


def _auto(est: OffsetEstimate | None, name: str, ref_file: str, what: str, period: float) -> float:
    """The offset ``time_offset: auto`` applies to source ``name``: the estimate, when the motion fixes
    it to AGREE_SAMPLES samples (of the slower file, ``period`` s); else one line of MapError."""
    pre = f"source {name!r}: time_offset: auto: "
    if est is None:
        raise MapError(pre + f"no motion shared with {ref_file} ({what}: one of them does not move); "
                       "state the offset in s")
    if not est.fixed:
        raise MapError(pre + est.why + "; state the offset in s")
    if not est.se_s <= AGREE_SAMPLES * period:
        raise MapError(pre + f"the motion fixes the offset only to ± {est.se_s:.2g} s "
                       f"({est.se_s / period:.2g} samples) about {est.offset_s:+.4g} s ({what}, r = {est.r:.2f}); "
                       "state the offset in s")
    return est.offset_s


def _words(stream: str) -> str:
    return {"markers": "marker speed", "pots": "pot speed"}.get(stream, "joint speed")


def _channel_rates(stream: str, time: np.ndarray, data: np.ndarray, rate: float) -> tuple | None:
    """(grid (N,), rates (N, C)) of a stream's channels on a uniform grid at ``rate`` Hz, or None when
    too few samples. data: (T, K[, 3]). Each channel is put on the grid (gaps filled linearly),
    low-passed below ENVELOPE_HZ (differences of raw samples are mostly noise) and differentiated
    (``qd`` is a rate already); a marker gives three channels, its coordinates."""
    if data.shape[0] < 8:
        return None
    grid = uniform_grid(time[0], time[-1], rate)
    flat = resample(data.reshape(data.shape[0], -1), time, grid)
    ok = np.isfinite(flat)
    keep = ok.sum(axis=0) >= 8
    if not keep.any():
        return None
    idx = np.arange(grid.size)
    flat = np.column_stack([np.interp(idx, idx[ok[:, k]], flat[ok[:, k], k]) for k in np.flatnonzero(keep)])
    try:
        smooth = lowpass(flat, rate, min(ENVELOPE_HZ, 0.4 * rate), order=2)
    except LogFormatError:  # too few samples to filter
        return None
    v = smooth if stream == "qd" else np.gradient(smooth, 1.0 / rate, axis=0)
    if stream == "markers":  # unseen markers' columns back, as NaN
        every = np.full((grid.size, keep.size), np.nan)
        every[:, keep] = v
        v = every
    return grid, v


def motion_speed(stream: str, time: np.ndarray, data: np.ndarray, rate: float) -> tuple | None:
    """(grid (N,), speed (N,)) of one stream on a uniform grid at ``rate`` Hz, or None when it does not
    move. data: (T, K[, 3]). Markers give their mean speed (m/s in the file's unit), other streams the
    norm of their unit-spread rates (:func:`_channel_rates`)."""
    rates = _channel_rates(stream, time, data, rate)
    if rates is None:
        return None
    grid, v = rates
    if stream == "markers":  # each seen marker's speed, averaged
        return grid, np.nanmean(np.linalg.norm(v.reshape(grid.size, -1, 3), axis=2), axis=1)
    spread = v.std(axis=0)
    moving = spread > 0
    return (grid, np.linalg.norm(v[:, moving] / spread[moving], axis=1)) if moving.any() else None


def motion_envelope(stream: str, time: np.ndarray, data: np.ndarray, rate: float) -> tuple | None:
    """(grid (N,), envelope (N,)) of one stream on a uniform grid at ``rate`` Hz, or None when it does
    not move: the norm of its channels' rates (:func:`_channel_rates`), each scaled to unit spread
    (a marker's coordinates by at least MARKER_SPREAD_FLOOR of the largest coordinate's spread), so
    that the mocap's and a logger's envelopes are alike."""
    rates = _channel_rates(stream, time, data, rate)
    if rates is None:
        return None
    grid, v = rates
    v = v[:, np.isfinite(v).all(axis=0)]
    spread = v.std(axis=0) if v.shape[1] else np.zeros(0)
    if stream == "markers" and spread.size:
        spread = np.maximum(spread, MARKER_SPREAD_FLOOR * spread.max())
    moving = spread > 0
    return (grid, np.linalg.norm(v[:, moving] / spread[moving], axis=1)) if moving.any() else None


def estimate_offset(a, b, names=("", ""), signals: str = "") -> OffsetEstimate:
    """The offset of ``b`` = (grid, envelope) against ``a`` (grids at one rate): the top of the surest
    correlation's peak where the motion fixes it (module docstring), else an estimate with
    ``offset_s`` None and the reason in ``why``."""
    (ga, xa), (gb, xb) = a, b
    rate = 1.0 / float(ga[1] - ga[0])
    tau = _integral_time(xa, xb)
    least = max(MIN_OVERLAP * min(xa.size, xb.size), MIN_INDEPENDENT * tau)
    r, n = _pearson_by_shift(xa, xb, int(np.ceil(least)))
    lag0 = float(ga[0] - gb[0]) - (xb.size - 1) / rate  # s at index 0: a[j + m] meets b[j] at index m + len(b) - 1

    def shift_s(k: float) -> float:
        return lag0 + k / rate

    est = OffsetEstimate(names[0], names[1], None, float("nan"), signals)
    if not np.isfinite(r).any():
        return replace(est, why=f"too little shared motion: no shift leaves {least / rate:.3g} s of overlap, "
                                f"{MIN_INDEPENDENT:g} times the motion's integral time ({tau / rate:.2g} s; a motion "
                                "that repeats has a long one)")
    z = np.arctanh(np.clip(r, -0.999999, 0.999999))
    se = 1.0 / np.sqrt(np.maximum(n / tau - 3.0, 1.0))  # Fisher's z: 1 / sqrt(n_eff - 3)
    k = int(np.argmax(np.where(np.isfinite(r), z / se, -np.inf)))  # the surest correlation: r weighed by overlap
    est = replace(est, r=float(r[k]), best_s=shift_s(k), overlap_s=float(n[k]) / rate)
    if r[k] < MIN_CORRELATION:
        return replace(est, why=f"no motion shared (correlation of {signals or 'the envelopes'} {r[k]:.2f} where "
                                f"surest, below {MIN_CORRELATION})")
    # Could shift m be the true one, and k the motion repeating (or noise)? Then r at k would be r_m times
    # the motion's autocorrelation at their distance: k must lead that by MARGIN standard errors.
    repeat = _repeat(xa, xb, tau, r.size)[np.abs(np.arange(r.size) - k)]
    lead = (z[k] - np.arctanh(np.clip(repeat * r, -0.999999, 0.999999))) / np.hypot(se[k], se)
    lead[~np.isfinite(r)] = np.inf
    close = lead < MARGIN  # shifts that fit about as well as k: its own peak, and any other
    apart = np.flatnonzero(~close)
    lo, hi = int(apart[apart < k].max(initial=-1)) + 1, int(apart[apart > k].min(initial=r.size))
    close[lo:hi] = False
    if close.any():
        rival = int(np.argmin(np.where(close, lead, np.inf)))
        return replace(est, rival_s=shift_s(rival), rival_r=float(r[rival]), why=(
            f"the motion does not fix the offset (it repeats, or too little of it is shared): "
            f"{shift_s(rival):+.4g} s fits about as well as {shift_s(k):+.4g} s (r = {r[rival]:.2f} over "
            f"{n[rival] / rate:.3g} s vs {r[k]:.2f} over {n[k] / rate:.3g} s)"))
    k = lo + int(np.nanargmax(r[lo:hi]))  # the top of k's peak
    curve = (r[k - 1] - 2 * r[k] + r[k + 1]) * rate**2 if 0 < k < r.size - 1 else np.nan  # r'' (1/s^2)
    se_s = np.sqrt((1 - r[k] ** 2) / (n[k] / tau * r[k] * -curve)) if curve < 0 else np.inf
    return replace(est, offset_s=shift_s(_peak(r, k)), se_s=float(se_s), r=float(r[k]), best_s=shift_s(k),
                   overlap_s=float(n[k]) / rate)


def grid_rate(*times: np.ndarray) -> float:
    """The rate both speeds are put on: the faster file's, at most MAX_GRID_HZ."""
    return min(MAX_GRID_HZ, max(1.0 / float(np.median(np.diff(t))) for t in times))


def _peak(r: np.ndarray, k: int) -> float:
    """Index ``k`` of r's highest point, refined between grid steps by a parabola through it and its
    neighbours."""
    if 0 < k < r.size - 1 and np.isfinite(r[k - 1]) and np.isfinite(r[k + 1]):
        den = r[k - 1] - 2 * r[k] + r[k + 1]
        return k + (0.5 * (r[k - 1] - r[k + 1]) / den if den < 0 else 0.0)
    return float(k)


def _repeat(a: np.ndarray, b: np.ndarray, tau: float, size: int) -> np.ndarray:
    """(size,): how much the motion repeats itself d samples on, for d < size: the larger of the two
    envelopes' autocorrelations at lag d, each over the samples d apart (not shrunk towards 0 at long
    lags) and raised by its standard error sqrt(tau / (N - d)), within [0, 1]; 1 where neither
    envelope has 8 samples d apart."""
    out = np.full(size, -np.inf)
    for x in (a, b):
        d = np.arange(min(size, x.size - 8))
        c = _autocovariance(x, d.size - 1) / (x.size - d)
        if d.size and c[0] > 0:
            out[:d.size] = np.maximum(out[:d.size], c / c[0] + np.sqrt(tau / (x.size - d)))
    return np.clip(np.where(np.isfinite(out), out, 1.0), 0.0, 1.0)


def _autocovariance(x: np.ndarray, lags: int) -> np.ndarray:
    """(lags + 1,): sum_t (x_t - x̄)(x_{t+d} - x̄) for d = 0..lags, by FFT."""
    x = x - x.mean()
    return correlate(x, x, mode="full", method="fft")[x.size - 1:x.size + max(lags, -1)]


def _integral_time(a: np.ndarray, b: np.ndarray) -> float:
    """The envelopes' integral time in samples, 1 + 2 sum_k (1 - k / (L + 1)) rho_a(k) rho_b(k) for k up
    to L, a quarter of the shorter one: Bartlett's variance of a cross-correlation of autocorrelated
    series (Var r = tau / n where they share no motion), with Newey and West's taper."""
    lags = max(min(a.size, b.size) // 4, 1)

    def acf(x):
        c = _autocovariance(x, lags)
        return c / c[0] if c[0] > 0 else np.zeros(lags + 1)

    k = np.arange(1, lags + 1)
    return max(1.0, 1.0 + 2.0 * float(np.sum((1 - k / (lags + 1)) * (acf(a) * acf(b))[1:])))


def _pearson_by_shift(a: np.ndarray, b: np.ndarray, min_overlap: int):
    """(r, n): Pearson's r of a[j + m] against b[j] over their overlap, for every shift m (index
    m + len(b) - 1), NaN where the overlap is shorter than ``min_overlap``; and the overlap's length.
    Sums over each overlap from cumulative sums, the cross sums by FFT (``scipy.signal.correlate``)."""
    a, b = a - a.mean(), b - b.mean()  # r does not change; the sums' round-off does
    na, nb = a.size, b.size
    m = np.arange(-(nb - 1), na)
    lo_a, hi_a = np.maximum(m, 0), np.minimum(na, nb + m)  # a's overlapping slice
    lo_b, hi_b = lo_a - m, hi_a - m
    n = (hi_a - lo_a).astype(np.float64)

    def window_sums(x, lo, hi):
        c = np.concatenate([[0.0], np.cumsum(x)])
        return c[hi] - c[lo]

    sa, saa = window_sums(a, lo_a, hi_a), window_sums(a * a, lo_a, hi_a)
    sb, sbb = window_sums(b, lo_b, hi_b), window_sums(b * b, lo_b, hi_b)
    sab = correlate(a, b, mode="full", method="fft")
    with np.errstate(invalid="ignore", divide="ignore"):
        cov = sab - sa * sb / n
        var = (saa - sa * sa / n) * (sbb - sb * sb / n)
        r = cov / np.sqrt(var)
    r[(n < max(min_overlap, 8)) | ~(var > 0)] = np.nan
    return r, n
