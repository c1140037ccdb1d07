"""Signal steps of an import: resampling with stated interpolation, zero-phase filtering, derivatives.

scipy.signal is imported inside the functions that need it (``diegocal --help`` stays fast).
"""

from __future__ import annotations

import numpy as np

from diegocal.errors import LogFormatError


def is_uniform(time: np.ndarray, tolerance: float = 0.01) -> bool:
    """True when every step is within ``tolerance`` (relative) of the median step."""
    if time.shape[0] < 3:
        return True
    steps = np.diff(time)
    median = float(np.median(steps))
    return bool(np.abs(steps - median).max() <= tolerance * median)


def uniform_rate(time: np.ndarray) -> float:
    """The rate a jittered series is put on before filtering: 1 / median step, rounded to 1 Hz
    (to 3 significant digits below 1 Hz)."""
    rate = 1.0 / float(np.median(np.diff(time)))
    return float(round(rate)) if rate >= 1.0 else float(f"{rate:.3g}")


def uniform_grid(start: float, stop: float, rate_hz: float) -> np.ndarray:
    """start + k / rate_hz for every k that stays within [start, stop] (1e-9 s tolerance)."""
    n = int(np.floor((stop - start) * rate_hz + 1e-9)) + 1
    return start + np.arange(max(n, 0)) / rate_hz


def resample(x: np.ndarray, t: np.ndarray, time: np.ndarray, method: str = "linear",
             max_gap_s: float | None = None) -> np.ndarray:
    """Values of ``x`` (T, ...) sampled at ``t`` (T,), s, read at ``time`` (N,) within [t[0], t[-1]].

    ``linear``: the straight line between the two samples around each time (``numpy.interp``'s
    formula; a time that hits a sample returns it exactly); ``nearest``: the closer sample;
    ``previous``: the last sample at or before (zero-order hold). NaN in a sample used gives NaN.
    A time that falls between two samples more than ``max_gap_s`` apart gives NaN: a gap is not
    bridged. Returns (N, ...).
    """
    t = np.asarray(t, dtype=np.float64)
    time = np.asarray(time, dtype=np.float64)
    if time.size and (time[0] < t[0] - 1e-12 or time[-1] > t[-1] + 1e-12):
        raise ValueError("resample: times outside the samples' span")
    flat = x.reshape(x.shape[0], -1)
    hit = np.searchsorted(t, time, side="left").clip(0, t.shape[0] - 1)
    exact = t[hit] == time
    j = (np.searchsorted(t, time, side="right") - 1).clip(0, max(t.shape[0] - 2, 0))
    if t.shape[0] == 1:
        out = np.repeat(flat[:1], time.shape[0], axis=0)
        return out.reshape((time.shape[0],) + x.shape[1:])
    t0, t1 = t[j], t[j + 1]
    if method == "linear":
        slope = (flat[j + 1] - flat[j]) / (t1 - t0)[:, None]
        out = slope * (time - t0)[:, None] + flat[j]
    elif method == "nearest":
        out = flat[np.where(time - t0 <= t1 - time, j, j + 1)]
    elif method == "previous":
        out = flat[np.where(time >= t1, j + 1, j)]
    else:
        raise ValueError(f"unknown interpolation {method!r}")
    out[exact] = flat[hit[exact]]
    if max_gap_s is not None:
        out[~exact & (t1 - t0 > max_gap_s)] = np.nan
    return out.reshape((time.shape[0],) + x.shape[1:])


def default_max_gap(t: np.ndarray) -> float:
    """Ten median sample periods: the longest step an import bridges unless the map says otherwise."""
    return 10.0 * float(np.median(np.diff(t))) if t.shape[0] > 1 else np.inf


def lowpass(x: np.ndarray, rate_hz: float, cutoff_hz: float, order: int = 4) -> np.ndarray:
    """Zero-phase Butterworth low-pass along axis 0 (``scipy.signal.sosfiltfilt``: forward and back,
    so no lag and twice the order). x: (T, K), uniformly sampled at ``rate_hz``."""
    from scipy.signal import butter, sosfiltfilt

    if not 0 < cutoff_hz < 0.5 * rate_hz:
        raise LogFormatError(f"filter cut-off {cutoff_hz:g} Hz must be below half the sample rate "
                             f"({0.5 * rate_hz:g} Hz)")
    sos = butter(order, cutoff_hz, fs=rate_hz, output="sos")
    pad = 3 * (2 * sos.shape[0] + 1)  # sosfiltfilt's default padding
    if x.shape[0] <= pad:
        raise LogFormatError(f"{x.shape[0]} samples are too few to filter (order {order} needs more than {pad})")
    return sosfiltfilt(sos, x, axis=0)


def derivatives(q: np.ndarray, rate_hz: float, cutoff_hz: float | None, order: int = 4):
    """q, qd, qdd (each (T, n)) from positions (T, n) sampled uniformly at ``rate_hz``.

    With a cut-off: zero-phase low-pass of q, central differences (``numpy.gradient``, one-sided
    at the ends), and the same low-pass after each differentiation; without: plain central
    differences.
    """
    dt = 1.0 / rate_hz

    def smooth(x):
        return x if cutoff_hz is None else lowpass(x, rate_hz, cutoff_hz, order)

    if q.shape[0] < 3:
        raise LogFormatError(f"{q.shape[0]} samples are too few to differentiate")
    qf = smooth(q)
    qd = smooth(np.gradient(qf, dt, axis=0))
    qdd = smooth(np.gradient(qd, dt, axis=0))
    return qf, qd, qdd


def excitation_window(qd: np.ndarray, rate_hz: float, threshold: float = 0.02,
                      margin_s: float = 0.25) -> tuple[int, int]:
    """Sample range [start, stop) where any joint moves faster than ``threshold`` (rad/s or m/s),
    widened by ``margin_s`` on each side; the whole range when nothing moves. qd: (T, n)."""
    moving = np.flatnonzero(np.abs(qd).max(axis=1) > threshold)
    if moving.size == 0:
        return 0, qd.shape[0]
    pad = int(round(margin_s * rate_hz))
    return max(0, int(moving[0]) - pad), min(qd.shape[0], int(moving[-1]) + 1 + pad)
