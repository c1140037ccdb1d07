"""The Show step: what a model gets wrong, channel by channel, before any cause is named.

For each channel and each state variable the domain names (its own joint's angle and velocity,
the sign of the velocity, a lagged valve command, time), the residual's mean per quantile bin of
the variable, fitted on the training samples, is tested on the validation samples like any
candidate (:func:`~diegocal.diagnose.selection.evaluate_candidates`): a binned mean is the most flexible
term that depends on that variable alone. Beside it, the residual's correlation time (whiteness)
and a CUSUM change-point test in time (:func:`~diegocal.diagnose.stats.change_point`).

The same binned terms, run on what remains after the named causes, are the ``unexplained``
findings: structure that is significant and large, but that no term of the vocabulary explains.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace

import numpy as np

from diegocal.diagnose.selection import evaluate_candidates
from diegocal.diagnose.stats import autocorrelation_time, bin_index, binned_means, change_point, quantile_edges
from diegocal.diagnose.types import Candidate
from diegocal.evaluate import sub_blocks
from diegocal.terms import Parameter, Region, Term


class BinColumns(Mapping):
    """A binned candidate's columns, ``{channel: (T, k) or (T, d, k)}``, built from the samples'
    bin indices each time they are read: a candidate holds a small integer per sample and
    variable instead of T·k floats, so that every channel × variable of a long log can be
    tested in one round (a 10-minute, 1 kHz log: 600,000 rows × 20 bins × 8 bytes = 96 MB
    each, dense).

    ``index``: per variable, (T,) its bin 0..B-1 or -1 where missing (a NaN row), and B;
    ``skip_first`` drops each variable's first bin (an additive model with ``constant``, a
    leading column of ones); ``d`` axes of the residual (1: a scalar channel, columns (T, k);
    d > 1: block-diagonal (T, d, k·d), each axis its own copy of the columns).
    """

    def __init__(self, channel: str, index: list, d: int = 1, skip_first: bool = False, constant: bool = False):
        self.channel, self.index, self.d = channel, index, d
        self.skip_first, self.constant = skip_first, constant

    def _onehot(self, samples=slice(None)) -> np.ndarray:
        index = [(b[samples], B) for b, B in self.index]
        T = index[0][0].size
        parts = [np.ones((T, 1))] if self.constant else []
        for b, B in index:
            cut = int(self.skip_first)
            x = np.zeros((T, B - cut))
            ok = b >= cut
            x[np.flatnonzero(ok), b[ok] - cut] = 1.0
            parts.append(x)
        out = np.hstack(parts)
        for b, _ in index:
            out[b < 0] = np.nan
        return out

    def rows(self, channel: str, samples) -> np.ndarray:
        """``self[channel][samples]``, built on those samples only (a fit on the training rows)."""
        return self._axes(channel, self._onehot(samples))

    def __getitem__(self, channel: str) -> np.ndarray:
        return self._axes(channel, self._onehot())

    def _axes(self, channel: str, x: np.ndarray) -> np.ndarray:
        if channel != self.channel:
            raise KeyError(channel)
        if self.d == 1:
            return x
        k = x.shape[1]
        cols = np.zeros((x.shape[0], self.d, k * self.d))
        for a in range(self.d):
            cols[:, a, a * k : (a + 1) * k] = x
        return cols

    def __contains__(self, channel) -> bool:  # Mapping's own would build the columns to see
        return channel == self.channel

    def __iter__(self):
        yield self.channel

    def __len__(self) -> int:
        return 1


def _bins(x: np.ndarray, edges: np.ndarray) -> tuple[np.ndarray, int]:
    """(bin index (T,) in the smallest integer type, number of bins) of x for ``edges``."""
    B = edges.size - 1
    return bin_index(x, edges).astype(np.int16 if B < 2**15 else np.int64), B


def binned_candidate(res, channel: str, variable: str, train: np.ndarray, n_bins: int):
    """A Candidate whose columns are the indicators of the quantile bins (from the training
    samples) of ``variable``, one per bin and residual axis (:class:`BinColumns`); its term is
    ``unexplained`` on the channel (``extra.edges`` holds the bin edges)."""

    x = np.asarray(res.variables[variable], float)
    edges = quantile_edges(x[train], n_bins)
    index, B = _bins(x, edges)
    r = np.asarray(res.channels[channel])
    d = 1 if r.ndim == 1 else r.shape[1]
    names = [f"bin{k}" for k in range(B)] if d == 1 else [f"bin{k}.{a}" for a in range(d) for k in range(B)]
    term = Term(
        "unexplained",
        channel,
        tuple(Parameter(n) for n in names),
        Region(variable, float(edges[0]), float(edges[-1])),
        {"edges": [float(e) for e in edges]},
    )
    return Candidate(term, BinColumns(channel, [(index, B)], d), family="")


#: Quantile levels of |x| on each side of zero for the bins of a variable that takes both signs
#: (a velocity): fine near zero, where friction changes shape within a few hundredths of rad/s.
SIGNED_LEVELS = (0.0, 0.005, 0.01, 0.02, 0.04, 0.08, 0.16, 0.32, 0.64, 1.0)


def signed_edges(x: np.ndarray, n_bins: int) -> np.ndarray:
    """Bin edges of ``x`` that never straddle 0 when x takes both signs with some mass on each
    (a velocity): quantiles :data:`SIGNED_LEVELS` of |x| on each side, fine near zero, so that
    structure there (friction's shape) is neither averaged away between the two signs nor over a
    wide bin; plain quantile edges (``n_bins``) otherwise."""
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    neg, pos = -x[x < 0], x[x > 0]
    if min(neg.size, pos.size) < 0.1 * max(x.size, 1):
        return quantile_edges(x, n_bins)
    lo = -np.quantile(neg, SIGNED_LEVELS)[::-1]
    hi = np.quantile(pos, SIGNED_LEVELS)
    return np.unique(np.concatenate([lo[:-1], [0.0], hi[1:]]))


def flexible_candidate(res, channel: str, train: np.ndarray, n_bins: int):
    """The most flexible model of ``channel``'s residual in its state: an additive binned function
    of every variable the domain names for it and of its context (:func:`signed_edges` bins; a
    constant and each variable's bins but the first), a Candidate with an ``unexplained`` term. A
    named term that explains much less than this is a stand-in for structure of another shape: a
    spring on a joint whose angle merely correlates with the next joint's, which pulls a hose."""
    names = flexible_variables(res, channel)
    r = np.asarray(res.channels[channel])
    index, edges_of = [], {}
    for v in names:
        x = np.asarray(res.variables[v], float)
        edges = signed_edges(x[train], n_bins)
        b, B = _bins(x, edges)
        if B < 2:
            continue
        index.append((b, B))
        edges_of[v] = [float(e) for e in edges]
    if not index or r.ndim != 1:
        return None
    k = 1 + sum(B - 1 for _, B in index)
    term = Term("unexplained", channel, tuple(Parameter(f"f{i}") for i in range(k)), None, {"edges": edges_of})
    return Candidate(term, BinColumns(channel, index, skip_first=True, constant=True), family="")


def flexible_variables(res, channel: str) -> tuple:
    """The variables of ``channel``'s flexible model: its own, then its context's."""
    own = tuple(res.channel_variables.get(channel, ()))
    return own + tuple(v for v in res.context.get(channel, ()) if v not in own)


def region_of(tested, n_bins_axes: int | None = None) -> Region:
    """Where a significant binned term departs most: the contiguous run of bins around the bin
    of largest |mean|, extended while the neighbours exceed half of it (edges of the variable)."""
    term = tested.term
    edges, mag, _ = _bin_magnitudes(term)
    B = mag.size
    k = int(np.argmax(mag))
    lo = hi = k
    while lo > 0 and mag[lo - 1] > 0.5 * mag[k]:
        lo -= 1
    while hi < B - 1 and mag[hi + 1] > 0.5 * mag[k]:
        hi += 1
    return Region(term.region.variable, float(edges[lo]), float(edges[hi + 1]))


def unexplained_region(tested) -> Region:
    """Where an ``unexplained`` structure sits: from the first to the last bin whose |mean| is over
    half the largest (:func:`region_of`'s run when they are contiguous). A structure at both ends of
    the variable (a hose's torque linear in the next joint's angle) spans its range, not the end
    where it happens to be largest (a user trial: q.elbow 0.64-1.58 of -1.32-1.58)."""
    term = tested.term
    edges, mag, whole = _bin_magnitudes(term)
    if not whole:
        return region_of(tested)
    over = np.flatnonzero(mag > 0.5 * mag.max())
    return Region(term.region.variable, float(edges[over[0]]), float(edges[over[-1] + 1]))


def _bin_magnitudes(term) -> tuple[np.ndarray, np.ndarray, bool]:
    """A binned term's edges (B + 1,), each bin's magnitude over its channels (B,), and whether its
    values are whole rows of B bins (else the first B values are read as one row)."""
    edges = np.asarray(term.extra["edges"], float)
    B = edges.size - 1
    whole = term.values.size % B == 0
    vals = term.values.reshape(-1, B) if whole else term.values[None, :B]
    return edges, np.sqrt((vals**2).sum(axis=0)), whole


def show(res, weights: dict, train, validation, shown, length: int, options, time=None, exclude=None) -> dict:
    """The Show step on residuals ``res``: per channel, per variable the binned test (fitted on
    ``train``, tested on ``validation``) and the curve (residual mean per bin on the ``shown``
    samples, with block bands over sub-blocks of ``length`` samples), the correlation time and the
    change-point test. Returns a plain mapping (diagnosis.yaml's ``residual_tests``)."""

    out = {}
    n_tests = sum(len(res.channel_variables.get(c, ())) for c in res.channels) or 1
    opts = replace(options, n_units=max(options.n_units, 1) * n_tests)
    shown_cl = sub_blocks(shown, length)
    seen_cl = sub_blocks(shown | train, length)
    for c, r in res.channels.items():
        r = np.array(r, float)
        if exclude and c in exclude:
            r[np.asarray(exclude[c], bool)] = np.nan
        scalar = r if r.ndim == 1 else np.linalg.norm(r, axis=1)
        entry = {"correlation_time_s": None, "variables": {}}
        if time is not None and time.size > 1:
            entry["correlation_time_s"] = float(autocorrelation_time(r[train]) * np.median(np.diff(time)))
        for v in res.channel_variables.get(c, ()):
            cand = binned_candidate(res, c, v, train, options.n_bins)
            tested = evaluate_candidates([cand], res, weights, train, validation, opts, exclude)
            x = np.asarray(res.variables[v], float)
            edges = np.asarray(cand.term.extra["edges"])
            curve = binned_means(np.where(shown, scalar, np.nan), x, shown_cl, edges, v)
            item = {"curve": curve.to_dict()}
            if tested:
                t = tested[0]
                item.update(
                    t=round(float(t.test.t), 2),
                    threshold_t=round(float(t.threshold), 2),
                    validation_gain=round(float(t.gain), 4),
                    significant=bool(t.significant),
                )
            entry["variables"][v] = item
        centred = scalar - np.nanmean(scalar[train]) if np.isfinite(scalar[train]).any() else scalar
        entry["change_point"] = _change(np.where(shown | train, centred, np.nan), seen_cl, time)
        velocity = next((v for v in res.channel_variables.get(c, ()) if v.startswith("qd.")), None)
        if velocity is not None and r.ndim == 1:  # friction's share: the residual times the direction of motion
            direction = np.sign(np.asarray(res.variables[velocity], float))
            signed = np.where(direction != 0, r * direction, np.nan)
            signed -= np.nanmean(signed[train]) if np.isfinite(signed[train]).any() else 0.0
            entry["change_point_signed"] = _change(np.where(shown | train, signed, np.nan), seen_cl, time)
        out[c] = entry
    return out


def _change(r: np.ndarray, clusters: np.ndarray, time) -> dict:
    """The CUSUM change-point test of ``r`` (:func:`~diegocal.diagnose.stats.change_point`) as
    diagnosis.yaml holds it: p, the statistic and the time of the largest departure."""
    cp = change_point(r, clusters)
    return {"p": float(cp.p), "statistic": round(cp.statistic, 3), "time": None if time is None else float(time[cp.at])}

