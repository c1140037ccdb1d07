"""Candidate selection: fit each candidate term on the training samples, test it on the validation
samples, choose one (issue #13, step 2 "Name the cause").

The residual channels are stacked as weighted rows (:class:`_Stack`: each channel divided by its
baseline training RMS, so that channels in different units share one least-squares problem and one
test); a candidate's columns are fitted by least squares with standard errors inflated by the
residual's correlation time, the best variant of each family on the training rows is tested out of
sample (:func:`~diegocal.diagnose.stats.out_of_sample_test`) against a Bonferroni threshold over the
families and units (:func:`evaluate_candidates`), and :func:`choose` applies the one-standard-error
rule among the significant ones. The data types (:class:`~diegocal.diagnose.engine.Candidate`,
:class:`~diegocal.diagnose.engine.Tested`) and the loop that calls this live in :mod:`.engine`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from diegocal.diagnose.stats import autocorrelation_time, critical_t, out_of_sample_test, paired_difference
from diegocal.diagnose.types import Candidate, EngineOptions, Residuals, Tested, column_rows
from diegocal.progress import Eta
from diegocal.terms import Parameter, Term


# ----------------------------------------------------------------------------- rows
class _Stack:
    """Residual channels as weighted rows on a set of samples.

    A channel's rows are its samples (T,) or its samples × axes (T·d,) in sample-major order; each
    is multiplied by the channel's weight (1 / its baseline training RMS) so that channels in
    different units (V and m) can share a least-squares problem and a test.
    """

    def __init__(self, res: Residuals, weights: dict, samples: np.ndarray, exclude: dict):
        self.res, self.weights, self.samples, self.exclude = res, weights, samples, exclude
        self.dims = {c: 1 if np.ndim(r) == 1 else int(np.shape(r)[1]) for c, r in res.channels.items()}

    def residual(self, channels) -> tuple[np.ndarray, np.ndarray]:
        """(rows,) weighted residual (NaN where missing or excluded) and (rows,) sample index."""
        parts, samp = [], []
        for c in channels:
            r = np.array(self.res.channels[c], float)
            if c in self.exclude:
                r[np.asarray(self.exclude[c], bool)] = np.nan
            r = r[self.samples] * self.weights[c]
            parts.append(r.reshape(-1))
            samp.append(np.repeat(self.samples, self.dims[c]))
        if not parts:
            return np.zeros(0), np.zeros(0, int)
        return np.concatenate(parts), np.concatenate(samp)

    def design(self, cols: dict | None, channels, k: int) -> np.ndarray:
        """(rows, k): the columns (channel -> (T, k) or (T, d, k)) in :meth:`residual`'s row order;
        zero rows for a channel the columns do not act on."""
        out = []
        for c in channels:
            n = self.samples.size * self.dims[c]
            x = column_rows(cols, c, self.samples)
            out.append(np.zeros((n, k)) if x is None else (np.asarray(x, float) * self.weights[c]).reshape(n, k))
        return np.vstack(out) if out else np.zeros((0, k))


def channel_weights(res: Residuals, train: np.ndarray) -> dict:
    out = {}
    for c, r in res.channels.items():
        x = np.asarray(r, float)[train]
        rms = float(np.sqrt(np.nanmean(x * x))) if np.isfinite(x).any() else 0.0
        out[c] = 1.0 / rms if rms > 0 and np.isfinite(rms) else 1.0
    return out


# ----------------------------------------------------------------------------- candidates
@dataclass(frozen=True)
class _Fit:
    coef: np.ndarray  # (k + k0,)
    se: np.ndarray  # (k,) standard errors of the term's parameters
    train_gain: float  # Σ r² − Σ (r − A coef)² on the training rows (weighted)


def _columns(cand: Candidate, stack: _Stack, channels) -> np.ndarray:
    k = cand.n_params
    A = stack.design(cand.columns, channels, k)
    if cand.refit:
        k0 = next(iter(np.shape(v)[-1] for v in cand.refit.values()))
        A = np.hstack([A, stack.design(cand.refit, channels, k0)])
    return A


def _fit(cand: Candidate, stack: _Stack, channels) -> _Fit | None:
    r, samp = stack.residual(channels)
    A = _columns(cand, stack, channels)
    ok = np.isfinite(r) & np.isfinite(A).all(axis=1)
    if ok.sum() <= A.shape[1] + 2:
        return None
    A, r, samp = A[ok], r[ok], samp[ok]
    coef, *_ = np.linalg.lstsq(A, r, rcond=None)
    e = r - A @ coef
    gain = float(r @ r - e @ e)
    dof = max(r.size - A.shape[1], 1)
    # correlated residuals: the variance of a sum is inflated by the correlation time
    tau = autocorrelation_time(np.bincount(samp, weights=e)[np.bincount(samp) > 0])  # per sample, in order
    s2 = float(e @ e) / dof * max(tau, 1.0)
    cov = np.linalg.pinv(A.T @ A) * s2
    k = cand.n_params
    return _Fit(coef, np.sqrt(np.maximum(np.diag(cov)[:k], 0.0)), gain)


def _test(cand: Candidate, fit: _Fit, stack: _Stack, channels, validation: np.ndarray):
    r, samp = stack.residual(channels)
    A = _columns(cand, stack, channels)
    ok = np.isfinite(r) & np.isfinite(A).all(axis=1)
    return out_of_sample_test(r[ok], A[ok] @ fit.coef, samp[ok], validation)


def _channel_gains(cand: Candidate, fit: _Fit, stack: _Stack, channels) -> tuple[list[float], list[float]]:
    """Per channel of ``channels``: the fraction of its validation error the fitted correction
    removes, and the correction's energy there."""
    r, _ = stack.residual(channels)
    a = _columns(cand, stack, channels) @ fit.coef
    sizes = [stack.samples.size * stack.dims[c] for c in channels]
    edges = np.concatenate([[0], np.cumsum(sizes)])
    gains, energy = [], []
    for i in range(len(channels)):
        ri, ai = r[edges[i] : edges[i + 1]], a[edges[i] : edges[i + 1]]
        ok = np.isfinite(ri) & np.isfinite(ai)
        before = float(ri[ok] @ ri[ok])
        gains.append(1.0 - float((ri[ok] - ai[ok]) @ (ri[ok] - ai[ok])) / before if before > 0 else 0.0)
        energy.append(float(ai[ok] @ ai[ok]))
    return gains, energy


def _own_gain(cand: Candidate, fit: _Fit, stack: _Stack, channels) -> tuple[float | None, tuple | None]:
    """Fraction of the validation error of the candidate's own channel (its term's channel, when
    the fitted correction acts on it more than on any other) that the correction removes; None
    when it has none (a joint's link offset seen mostly by markers, whatever a pot of the same
    name gets from it). Second: (channel, its gain) where the correction acts most, when the term
    names no channel it acts on (a payload on a link): the channel it is judged on."""
    gains, energy = _channel_gains(cand, fit, stack, channels)
    i = int(np.argmax(energy))
    own = cand.term.channel
    if own not in cand.columns or own not in channels:
        return None, (channels[i], gains[i])
    j = list(channels).index(own)
    return (gains[j] if energy[j] >= energy[i] else None), None


def _candidate_channels(cand: Candidate) -> tuple[str, ...]:
    names = list(cand.columns)
    for c in cand.refit or {}:
        if c not in names:
            names.append(c)
    return tuple(names)


def evaluate_candidates(
    candidates: list[Candidate],
    res: Residuals,
    weights: dict,
    train: np.ndarray,
    validation: np.ndarray,
    options: EngineOptions,
    exclude: dict | None = None,
) -> list[Tested]:
    """Fit every candidate on the ``train`` samples (one variant per family: the best training
    fit), test it on the ``validation`` samples, Bonferroni over the families (and units)."""
    exclude = exclude or {}
    tr = _Stack(res, weights, np.flatnonzero(train), exclude)
    va = _Stack(res, weights, np.flatnonzero(validation), exclude)
    best: dict[str, tuple[Candidate, _Fit]] = {}
    eta = Eta(len(candidates))  # a long round says how far it is, with the time left
    for i, cand in enumerate(candidates):
        key = cand.family or f"#{i}"
        fit = _fit(cand, tr, _candidate_channels(cand))
        if options.progress is not None and eta.due(i + 1):
            options.progress(f"candidate terms fitted: {eta.text(i + 1)}")
        if fit is None:
            continue
        if key not in best or fit.train_gain > best[key][1].train_gain:
            best[key] = (cand, fit)
    n_tests = max(len(best), 1) * max(options.n_units, 1)
    out = []
    for cand, fit in best.values():
        chans = _candidate_channels(cand)
        test = _test(cand, fit, va, chans, validation)
        thr = critical_t(options.alpha, n_tests, test.df)
        k = cand.n_params
        term = cand.term.with_linear_values(fit.coef[:k], fit.se)
        own, strongest = _own_gain(cand, fit, va, chans) if len(chans) > 1 else (None, None)
        gain = test.gain if own is None else max(own, test.gain)
        sig = bool(test.t > thr and gain >= options.min_gain)
        out.append(Tested(term, tuple(cand.columns), test, thr, sig, k, cand, None if own is None else gain, strongest))
    out.sort(key=lambda t: -(t.test.sse_before - t.test.sse_after))
    return out


class JoinedColumns(Mapping):
    """A common cause's columns, channel -> (T, K) or (T, d, K): its members' columns side by
    side (each member its own slice of the K parameters, zero elsewhere), built when read and, for
    a fit or a test (:meth:`rows`), on the samples asked for only: the members' columns are held
    already, and a full-length copy of all of them per channel is what a long log cannot afford.

    ``parts``: channel -> [(a member's columns mapping, its slice of the K columns)].
    """

    def __init__(self, parts: dict, K: int):
        self.parts, self.K = parts, K

    def rows(self, channel: str, samples) -> np.ndarray:
        return self._join(channel, samples)

    def __getitem__(self, channel: str) -> np.ndarray:
        return self._join(channel, slice(None))

    def _join(self, channel: str, samples) -> np.ndarray:
        out = None
        for cols, sl in self.parts[channel]:
            x = np.asarray(column_rows(cols, channel, samples))  # its own precision (kinematics: float32)
            x = x[..., None] if x.ndim == 1 else x
            if out is None:
                out = np.zeros((*x.shape[:-1], self.K), dtype=np.result_type(x.dtype, np.float32))
            out[..., sl] += x
        return out

    def __contains__(self, channel) -> bool:
        return channel in self.parts

    def __iter__(self):
        return iter(self.parts)

    def __len__(self) -> int:
        return len(self.parts)


def common_candidates(tested: list[Tested]) -> list[Candidate]:
    """One candidate per cause that more than one channel's best variant proposes with a positive
    validation gain: their columns side by side, each channel its own parameters (one cause acting
    on every joint at once, tested as one: more power than each channel alone, one test for the
    family-wise rate). Causes with re-fit columns are left alone."""
    by_cause: dict[str, list[Tested]] = {}
    for t in tested:
        if t.candidate.members or t.candidate.refit or t.test.gain <= 0:
            continue
        by_cause.setdefault(t.term.cause, []).append(t)
    out = []
    for cause, members in by_cause.items():
        channels = [t.term.channel for t in members]
        if len(members) < 2 or len(set(channels)) < len(channels):
            continue
        sizes = [t.candidate.n_params for t in members]
        at, parts, params = 0, {}, []
        for t, k in zip(members, sizes, strict=True):
            for c in t.candidate.columns:
                parts.setdefault(c, []).append((t.candidate.columns, slice(at, at + k)))
            params += [Parameter(f"{t.term.channel}.{p.name}", p.value, p.unit) for p in t.term.linear]
            at += k
        cols = JoinedColumns(parts, sum(sizes))
        term = Term(cause, "+".join(channels), tuple(params))
        out.append(Candidate(term, cols, family=f"common:{cause}", members=tuple(members)))
    return out


def choose(tested: list[Tested], validation: np.ndarray) -> Tested | None:
    """The significant candidate that removes the most validation error, unless a simpler one
    (fewer parameters) on the same channels is within one standard error of it (paired over the
    validation sub-blocks of the best one's test): then the simplest such (the one-SE rule)."""
    sig = [t for t in tested if t.significant]
    if not sig:
        return None
    best = max(sig, key=lambda t: t.test.sse_before - t.test.sse_after)
    simpler = []
    for t in sig:
        if t is best or t.n_params >= best.n_params or set(t.channels) != set(best.channels):
            continue
        mean, se, n = paired_difference(t.test.after, best.test.after, validation, best.test.length)
        if n >= 3 and mean <= se:  # the simpler one is worse by at most one standard error
            simpler.append(t)
    if simpler:
        return min(simpler, key=lambda t: (t.n_params, t.test.sse_after))
    return best
