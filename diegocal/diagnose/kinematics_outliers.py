"""Marker outliers, and the readings that only look like them (issue #31: a wrong name is worse
than ``unexplained``).

A marker outlier is a reading far off its neighbours' trend (:func:`outlier_flags`). The
residuals are taken at q tracked from every sensor, so a pot reading far off (a pot whose line
drops to 0 V for a sample or three) pulls q at that frame and moves every marker's prediction
with it: on a user trial (Kinova, Baxter, G1, Allegro, 25-s logs) the dropouts of one pot were
named ``marker_outliers`` on every marker. :func:`pot_carried` re-tracks the flagged frames from
the markers alone: a flag whose marker then fits, on a frame where a pot is far off the markers'
q, is the pot's, not the marker's, and is dropped. The pot's readings are left in (the vocabulary
has no pot fault to write them off with); the adapter says where they are.
"""

from __future__ import annotations

import warnings

import numpy as np
from scipy.stats import chi2

from diegocal.diagnose.kinematics_lin import running_median
from diegocal.stac.predict import predict

#: Half width (samples) of the running median a marker outlier is measured against.
OUTLIER_WINDOW = 8
#: A marker outlier is at least this many σ (its marker's own scale) off its neighbours' trend:
#: the chi² level of a family-wise 1 % assumes Gaussian residuals, and the tracked residuals' tails
#: are heavier on a large robot (clean 60-s Diego San logs: 12-16 readings beyond 5 σ where chi²
#: expects 2, the largest at 5.6-5.8 σ against chi²'s 6.0 σ); on the finger they are chi²'s (the
#: largest of 30 s at 4.8-5.3 σ against 5.6 σ). A practical margin over Diego San's largest, not
#: a derived level. Ghosts and reflections are centimetres off (tens of σ).
OUTLIER_SIGMAS = 7.0
#: A pot's spike lasts at most this many samples (a line dropping out for a sample or three);
#: a longer excursion is the model's to explain, not a reading to screen.
SPIKE_RUN = 4


def outlier_flags(rm: np.ndarray, n_tests: int, swapped: np.ndarray) -> tuple:
    """(flags (T, M) bool, threshold in σ, scale (M,) m²): the marker readings whose residual
    ``rm`` (T, M, 3) m is off its running median (a smooth model error is no outlier) by more than
    a family-wise 1 % chi²_3 level over ``n_tests`` readings, and at least OUTLIER_SIGMAS, each in
    its marker's own scale (the q tracking leaves markers on different links more or less of their
    noise: on Diego San the scales spread over ±15 %); ``swapped`` (T, M) readings are not tested."""
    e = rm - running_median(rm, OUTLIER_WINDOW)
    e2 = np.einsum("tmi,tmi->tm", e, e)
    ok = np.isfinite(e2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # a marker never seen: no scale
        scale = np.nanmedian(np.where(ok, e2, np.nan), axis=0) / chi2.median(3)
    scale = np.where(np.isfinite(scale) & (scale > 0), scale, np.inf)
    z2 = max(chi2.isf(0.01 / n_tests, 3), OUTLIER_SIGMAS**2)
    return ok & (e2 > z2 * scale) & ~swapped, float(np.sqrt(z2)), scale


def pot_spikes(rp: np.ndarray) -> np.ndarray:
    """(T, P) bool: pot residuals ``rp`` (T, P) far off their running median (more than
    OUTLIER_SIGMAS of the pot's own robust scale, 1.4826 × the median absolute deviation) in runs
    of at most SPIKE_RUN samples: isolated in time, as a line dropping out is. Not yet the pot's:
    the tracking spreads one pot's spike over its neighbours' residuals (:func:`pot_carried`)."""
    e = rp - running_median(rp, OUTLIER_WINDOW)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        s = 1.4826 * np.nanmedian(np.abs(e), axis=0)
    with np.errstate(invalid="ignore"):
        off = np.abs(e) > OUTLIER_SIGMAS * np.where(s > 0, s, np.inf)
    run = np.zeros(off.shape, int)  # the length of the run each sample is in
    for j in range(off.shape[1]):
        edges = np.flatnonzero(np.diff(np.concatenate([[0], off[:, j].astype(int), [0]])))
        for a, b in zip(edges[::2], edges[1::2], strict=True):
            run[a:b, j] = b - a
    return off & (run <= SPIKE_RUN)


def pot_carried(adapter, applied, cal, tracked: tuple, flag: np.ndarray, scale: np.ndarray, z: float) -> tuple:
    """(flags (T, M) bool, pots {pot: frames}): ``flag`` without the readings a pot carried.

    On each frame flagged, or with a pot's spike (:func:`pot_spikes`), q is tracked again from
    the markers alone, with the calibration ``cal`` of the mapped log ``applied`` fixed, from the
    running median of the ``tracked`` q (T, n) rad (the frame's own was pulled; ``tracked``: q
    and the pots' predictions (T, P) V at it). A flag is a pot's when its
    marker's residual at that q is back under the threshold ``z`` (σ of its marker's ``scale``)
    while some pot reads more than OUTLIER_SIGMAS of its type's σ off that q's prediction: the
    markers agree with each other, the pot does not. A real outlier stays off the markers' own q
    (other markers hold the link) and keeps its flag. ``pots``: each pot's readings so found, on
    the frames whose flags it carried or where it spikes."""
    q, pots_at_q = tracked
    rp_all = np.asarray(applied.log.stream("pots").data, float) - pots_at_q
    spikes = pot_spikes(rp_all) if rp_all.size else np.zeros((flag.shape[0], 0), bool)
    frames = np.flatnonzero(flag.any(axis=1) | spikes.any(axis=1))
    if frames.size == 0:
        return flag, {}
    T = flag.shape[0]
    near = np.zeros(T, bool)  # each frame with its neighbours: a pot's spike is off theirs
    for d in range(-OUTLIER_WINDOW, OUTLIER_WINDOW + 1):
        near[np.clip(frames + d, 0, T - 1)] = True
    ext = np.flatnonzero(near)
    both = ("pots", "markers")
    q0 = running_median(q, OUTLIER_WINDOW)[ext]
    pred = predict(applied.log.take(ext), applied.robot, cal, ("markers",), both, adapter.options, q_init=q0)
    r = np.full(rp_all.shape, np.nan)
    r[ext] = np.asarray(applied.log.stream("pots").data, float)[ext] - pred.pots
    e = r - running_median(r, OUTLIER_WINDOW)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        spread = 1.4826 * np.nanmedian(np.abs(e), axis=0)  # the markers' q leaves each pot this much
    floor = np.maximum(_pot_sigmas(adapter, cal), np.where(np.isfinite(spread), spread, np.inf))
    with np.errstate(invalid="ignore"):
        pot_off = np.abs(e[frames]) > OUTLIER_SIGMAS * floor
    at = np.searchsorted(ext, frames)
    markers = np.asarray(applied.log.stream("markers").data, float)[frames]
    rm = adapter.merged(applied, markers) - adapter.merged(applied, pred.markers[at])
    with np.errstate(invalid="ignore"):
        fits = np.einsum("tmi,tmi->tm", rm, rm) <= z**2 * scale
    carried = fits & pot_off.any(axis=1)[:, None] & flag[frames]
    out = flag.copy()
    out[frames] &= ~carried
    found = pot_off & (carried.any(axis=1)[:, None] | spikes[frames])
    pots = {n: frames[found[:, j]].tolist() for j, n in enumerate(adapter.pot_names) if found[:, j].any()}
    return out, pots


def retracked(adapter, fitted, bad: np.ndarray) -> tuple:
    """(calibration, (q (T, n) rad, pots (T, P) V), marker residuals (T, M, 3) m): ``fitted``'s
    model refitted by STAC (warm) on its training frames without the frames ``bad`` (T,) bool, and
    tracked on every frame. STAC's σ of a pot type is its residuals' RMS (eq. 2.17): a few pot
    readings volts off raise it tenfold (the G1 arm: 0.027 against 0.003 V clean), the tracking then
    follows the markers, whose residuals shrink and whose ordinary noise passes the outlier
    threshold on their own, shrunk scale."""
    new = adapter.fit_once(fitted.terms, fitted.train & ~bad, fitted, warm=True)
    xm, pred = adapter.marker_arrays(new)
    return new.cal, (new.q, new.pots), xm - pred


def _pot_sigmas(adapter, cal) -> np.ndarray:
    """(P,) each pot's σ by its type (``cal.sigma_by_group``, else ``cal.sigma_pots``); inf where
    not known (no pot is then called off)."""
    kinds = {p.name: p.kind for p in adapter.robot.sensors.pots}
    s = np.array([cal.sigma_by_group.get(kinds.get(n), cal.sigma_pots) for n in adapter.pot_names], float)
    return np.where(np.isfinite(s) & (s > 0), s, np.inf)

