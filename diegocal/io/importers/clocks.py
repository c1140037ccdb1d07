"""Two files, two clocks: the offset between them, estimated from the motion both record.

A motion capture PC and a robot's logger start their clocks apart; without an offset in the map
the import reads both on one time axis and keeps only their apparent overlap, misaligned. Each
file's *motion speed* tells when the robot moved: the mean speed of its markers, or the norm of
its joint (or pot) velocities, each channel scaled to unit spread so volts and radians weigh
alike. Both are put on one uniform grid and low-passed; the offset d maximises Pearson's r of

.. math:: r(d) = \\operatorname{corr}\\big(s_a(t),\\; s_b(t - d)\\big)

over every shift that leaves at least a quarter of the shorter file overlapping (r computed on the
overlap alone), refined between grid steps by a parabola through the peak. d is what to add to
file b's times (its ``time_offset``). Cross-correlation of speed envelopes is the usual way to
align mocap with other recordings (e.g. "time synchronisation by cross-correlation" in the
IMU-to-mocap literature); the speed, unlike the position, does not depend on where the mocap
frame is.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, replace

import numpy as np

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
#: The speed envelope keeps what moves slower than this (Hz): the robot's motion, not sensor noise.
ENVELOPE_HZ = 5.0
#: Finest grid the correlation is computed on (Hz): the envelopes hold nothing above ENVELOPE_HZ, and
#: the parabola through the peak resolves a fraction of a step.
MAX_GRID_HZ = 250.0


@dataclass(frozen=True)
class OffsetEstimate:
    """offset_s: to add to ``other``'s times to match ``reference``'s; r: the peak correlation."""

    reference: str
    other: str
    offset_s: float
    r: float
    signals: str  # "marker speed vs joint speed", for messages


def align_sources(series: list, sources: dict, clock_source: str | None, notes: list[str]):
    """Estimate each file's offset against the reference file (the clock's source, else the mocap
    file, else the first), apply it where the map says ``time_offset: auto``, warn where the files
    disagree by more than two samples. Returns (series, estimates)."""
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
        ref_speed = motion_speed(motion[ref].stream, motion[ref].time, motion[ref].data, rate)
        spec, other = sources[name].spec, motion_speed(s.stream, s.time, s.data, rate)
        what = (f"{_words(motion[ref].stream)} in {sources[ref].path.name} vs {_words(s.stream)} in "
                f"{sources[name].path.name}")
        est = None if ref_speed is None or other is None else estimate_offset(ref_speed, other, (ref, name), what)
        if spec.auto_offset:
            if est is None:
                raise MapError(f"source {name!r}: time_offset: auto finds no motion shared with "
                               f"{sources[ref].path.name} (correlation of {what} below {MIN_CORRELATION}); "
                               "state the offset in s")
            series = [replace(x, time=x.time + est.offset_s) if x.source == name else x for x in series]
            notes.append(f"time_offset: auto for {name}: {est.offset_s:+.6g} s ({what}, r = {est.r:.2f})")
        elif est is not None:
            period = max(float(np.median(np.diff(x.time))) for x in (motion[ref], s))
            if abs(est.offset_s) > 2 * period:
                log.warning("%s and %s: their clocks disagree by %+.4g s (%s, r = %.2f); set `time_offset: %.6g` "
                            "for source %r in the map, or `time_offset: auto`", sources[name].path.name,
                            sources[ref].path.name, est.offset_s, what, est.r, spec.time_offset + est.offset_s, name)
        if est is not None:
            estimates.append(est)
    return series, estimates


def _words(stream: str) -> str:
    return {"markers": "marker speed", "pots": "pot speed"}.get(stream, "joint speed")


def motion_speed(stream: str, time: np.ndarray, data: np.ndarray, rate: float) -> tuple | None:
    """(grid (N,), speed (N,)) of one stream on a uniform grid at ``rate`` Hz, or None when it does not
    move. data: (T, K[, 3]). Each channel is put on the grid (gaps filled linearly), low-passed below
    ENVELOPE_HZ (differences of raw samples are mostly noise), differentiated; markers give their mean
    speed, other streams the norm of their unit-spread rates."""
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
    if stream == "markers":  # each seen marker's speed, averaged
        every = np.full((grid.size, keep.size), np.nan)
        every[:, keep] = v
        return grid, np.nanmean(np.linalg.norm(every.reshape(grid.size, -1, 3), axis=2), axis=1)
    spread = v.std(axis=0)
    moving = spread > 0
    return (grid, np.linalg.norm(v[:, moving] / spread[moving], axis=1)) if moving.any() else None


def estimate_offset(a, b, names=("", ""), signals: str = "") -> OffsetEstimate | None:
    """The offset of ``b`` = (grid, speed) against ``a`` (grids at one rate); None when the peak
    correlation stays below MIN_CORRELATION."""
    (ga, xa), (gb, xb) = a, b
    rate = 1.0 / float(ga[1] - ga[0])
    r = _pearson_by_shift(xa, xb, int(MIN_OVERLAP * min(xa.size, xb.size)))
    k = int(np.nanargmax(r)) if np.isfinite(r).any() else -1
    if k < 0 or r[k] < MIN_CORRELATION:
        return None
    frac = 0.0
    if 0 < k < r.size - 1 and np.isfinite(r[k - 1]) and np.isfinite(r[k + 1]):
        den = r[k - 1] - 2 * r[k] + r[k + 1]
        frac = 0.5 * (r[k - 1] - r[k + 1]) / den if den < 0 else 0.0
    shift = k - (xb.size - 1) + frac  # a[j + shift] meets b[j]
    return OffsetEstimate(names[0], names[1], float(ga[0] - gb[0] + shift / rate), float(r[k]), signals)


def grid_rate(*times: np.ndarray) -> float:
    """The rate both speeds are put on: the faster file's, at most MAX_GRID_HZ."""
    return min(MAX_GRID_HZ, max(1.0 / float(np.median(np.diff(t))) for t in times))


def _pearson_by_shift(a: np.ndarray, b: np.ndarray, min_overlap: int) -> np.ndarray:
    """Pearson's r of a[j + m] against b[j] over their overlap, for every shift m (index m + len(b) - 1);
    NaN where the overlap is shorter than ``min_overlap``. Sums over each overlap from cumulative sums,
    the cross sums by FFT (``scipy.signal.correlate``)."""
    from scipy.signal import correlate

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
    return r
