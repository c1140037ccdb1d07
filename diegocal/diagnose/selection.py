"""Candidate selection: fit each candidate term on the training samples, test it on the validation
samples, choose one (issue #13, step 2 "Name the cause").

The residual channels are stacked as weighted rows (:class:`_Stack`: each channel divided by its
baseline training RMS, so that channels in different units share one least-squares problem and one
test); a candidate's columns are fitted by least squares with standard errors inflated by the
residual's correlation time, the best variant of each family on the training rows is tested out of
sample (:func:`~diegocal.diagnose.stats.out_of_sample_test`) against a Bonferroni threshold over the
families and units (:func:`evaluate_candidates`), and :func:`choose` applies the one-standard-error
rule and practical significance (SIMPLER_SHARE) among the significant ones. The data types
(:class:`~diegocal.diagnose.engine.Candidate`, :class:`~diegocal.diagnose.engine.Tested`) and the
loop that calls this live in :mod:`.engine`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace

import numpy as np

from diegocal.diagnose.limits import detectable
from diegocal.diagnose.stats import autocorrelation_time, critical_t, out_of_sample_test, paired_difference
from diegocal.diagnose.types import Candidate, EngineOptions, Residuals, Tested, column_rows
from diegocal.lstsq import TallLstsq
from diegocal.parallel import thread_imap, thread_map
from diegocal.progress import Eta
from diegocal.terms import Parameter, Term

# ----------------------------------------------------------------------------- rows
#: Samples per piece of a candidate's design: a fit or a test builds its columns this many samples
#: of one channel at a time (a flexible model of a 10-min log at 1 kHz has ~100 columns on 420,000
#: training samples: 340 MB whole, and lstsq copied it), never for all of them.
PIECE = 20000
#: A fit's per-sample sums of its columns (one pass over its rows) are held up to this many floats
#: (32 MB); a wider candidate on a longer log (a flexible model of a 10-min log at 1 kHz: ~100
#: columns on 480,000 samples) makes a second pass over its rows instead.
ONE_PASS_FLOATS = 4_000_000


class _Stack:
    """Residual channels as weighted rows on a set of samples.

    A channel's rows are its samples (T,) or its samples × axes (T·d,) in sample-major order; each
    is multiplied by the channel's weight (1 / its baseline training RMS) so that channels in
    different units (V and m) can share a least-squares problem and a test.
    """

    def __init__(self, res: Residuals, weights: dict, samples: np.ndarray, exclude: dict):
        self.res, self.weights, self.samples, self.exclude = res, weights, samples, exclude
        self.dims = {c: 1 if np.ndim(r) == 1 else int(np.shape(r)[1]) for c, r in res.channels.items()}
        self.length = len(next(iter(res.channels.values()))) if res.channels else 0  # T
        self._weighted: dict = {}  # channel -> its weighted residual rows, made once

    def channel(self, c: str) -> np.ndarray:
        """(n·d,) channel ``c``'s weighted residual on the samples (NaN where missing or excluded)."""
        if c not in self._weighted:
            r = np.array(self.res.channels[c], float)
            if c in self.exclude:
                r[np.asarray(self.exclude[c], bool)] = np.nan
            self._weighted[c] = (r[self.samples] * self.weights[c]).reshape(-1)
        return self._weighted[c]

    def pieces(self, cand: Candidate, channels):
        """(r, A, sample index) of the rows of ``channels``, PIECE samples of one channel at a
        time, rows where r and A are finite only: the weighted residual, the candidate's columns
        (then its re-fit columns) and each row's sample."""
        k, k0 = cand.n_params, _refit_width(cand)
        for c in channels:
            d, r = self.dims[c], self.channel(c)
            for i in range(0, self.samples.size, PIECE):
                sub = self.samples[i : i + PIECE]
                A = self._design(cand.columns, c, sub, k)
                if k0:
                    A = np.hstack([A, self._design(cand.refit, c, sub, k0)])
                ri = r[i * d : (i + sub.size) * d]
                ok = np.isfinite(ri) & np.isfinite(A).all(axis=1)
                yield ri[ok], A[ok], np.repeat(sub, d)[ok]

    def _design(self, cols, c: str, sub: np.ndarray, k: int) -> np.ndarray:
        """(n·d, k): the columns (channel -> (T, k) or (T, d, k)) of channel ``c`` on samples ``sub``,
        weighted; zero where the columns do not act on it."""
        n = sub.size * self.dims[c]
        x = column_rows(cols, c, sub)
        return np.zeros((n, k)) if x is None else (np.asarray(x, float) * self.weights[c]).reshape(n, k)

    def predicted(self, cand: Candidate, coef: np.ndarray, channels) -> dict:
        """{channel: (r, A @ coef, sample index)} over the finite rows of each of ``channels``, in
        :meth:`pieces`' order."""
        return {c: _joined([(r, A @ coef, s) for r, A, s in self.pieces(cand, (c,))]) for c in channels}


def _joined(parts: list) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(r, a, sample index) triples, one after another."""
    if not parts:
        return np.zeros(0), np.zeros(0), np.zeros(0, int)
    return tuple(np.concatenate(x) for x in zip(*parts, strict=True))


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


def _refit_width(cand: Candidate) -> int:
    """The number of the current model's directions re-fitted with the candidate (0: none)."""
    return next(iter(np.shape(v)[-1] for v in cand.refit.values())) if cand.refit else 0


def _fit(cand: Candidate, stack: _Stack, channels) -> _Fit | None:
    """Least squares of the residual on the candidate's columns, a piece of rows at a time
    (:class:`~diegocal.lstsq.TallLstsq`: lstsq's solution and rank cutoff, to rounding)."""
    ls, rr = TallLstsq(cand.n_params + _refit_width(cand)), 0.0
    # each sample's rows (channels, axes) summed, residual and columns: its summed error after the
    # fit is r_sum − A_sum coef without a second pass over the rows, where A_sum is small enough
    n = stack.samples.size
    one_pass = n * ls.p <= ONE_PASS_FLOATS
    r_sum, seen = np.zeros(n), np.zeros(n, bool)
    A_sum = np.zeros((n, ls.p)) if one_pass else None
    for r, A, samp in stack.pieces(cand, channels):
        ls.add(A, r)
        rr += float(r @ r)
        at = np.searchsorted(stack.samples, samp)
        seen[at] = True
        if one_pass:
            np.add.at(r_sum, at, r)
            np.add.at(A_sum, at, A)
    if ls.rows <= ls.p + 2:
        return None
    coef, ee = ls.solve()
    dof = max(ls.rows - ls.p, 1)
    if one_pass:
        e_sum = r_sum - A_sum @ coef
    else:
        e_sum = r_sum  # zeros
        for r, A, samp in stack.pieces(cand, channels):
            np.add.at(e_sum, np.searchsorted(stack.samples, samp), r - A @ coef)
    # correlated residuals: the variance of a sum is inflated by the correlation time
    tau = autocorrelation_time(e_sum[seen])  # per sample, in order
    s2 = ee / dof * max(tau, 1.0)
    cov = np.linalg.pinv(ls.gram()) * s2
    k = cand.n_params
    return _Fit(coef, np.sqrt(np.maximum(np.diag(cov)[:k], 0.0)), rr - ee)


def _test(predicted: dict, validation: np.ndarray):
    """The out-of-sample test on every channel's rows (:meth:`_Stack.predicted`) together."""
    return out_of_sample_test(*_joined(list(predicted.values())), validation)


def _channel_gains(predicted: dict) -> tuple[list[float], list[float]]:
    """Per channel of ``predicted`` (:meth:`_Stack.predicted`): the fraction of its validation
    error the fitted correction removes, and the correction's energy there."""
    gains, energy = [], []
    for r, a, _ in predicted.values():
        before = float(r @ r)
        gains.append(1.0 - float((r - a) @ (r - a)) / before if before > 0 else 0.0)
        energy.append(float(a @ a))
    return gains, energy


def _own_gain(cand: Candidate, predicted: dict) -> tuple[float | None, tuple | None, float | None]:
    """Fraction of the validation error of the candidate's own channel (its term's channel, when
    the fitted correction acts on it more than on any other) that the correction removes; None
    when it has none (a joint's link offset seen mostly by markers, whatever a pot of the same
    name gets from it). Second: (channel, its gain) where the correction acts most, when the term
    names no channel it acts on (a payload on a link): the channel it is judged on. Third: the
    gain on its own channel whatever acts most (a pot's curve moves the tracked joint, so its
    markers too): what a flexible model of that channel is weighed against."""
    channels = list(predicted)
    gains, energy = _channel_gains(predicted)
    i = int(np.argmax(energy))
    own = cand.term.channel
    if own not in cand.columns or own not in channels:
        return None, (channels[i], gains[i]), None
    j = list(channels).index(own)
    return (gains[j] if energy[j] >= energy[i] else None), None, gains[j]


def _limit(cand: Candidate, predicted: dict, test, threshold: float, weights: dict, min_gain: float) -> tuple | None:
    """``Tested.detectable``: on the candidate's own channel, its gain's there, else on the channel
    its correction acts on most, its gain's over all its channels (:func:`~.limits.detectable`);
    over ``cand.visible``, the share of its columns the model's own parameters left."""
    if not predicted:
        return None
    on = cand.term.channel
    if on in predicted:
        error = float(predicted[on][0] @ predicted[on][0])
    else:
        on = max(predicted, key=lambda c: float(predicted[c][1] @ predicted[c][1]))
        error = test.sse_before
    r, a, _ = predicted[on]
    rms, multiple, by = detectable(test.se, threshold, r, a, error, weights.get(on, 1.0), min_gain)
    return on, rms / cand.visible, multiple / cand.visible, by  # the effect's, before the model takes its part


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
    alongside: list[Tested] = (),
) -> list[Tested]:
    """Fit every candidate on the ``train`` samples (one variant per family: the best training
    fit, or every variant that ties with it exactly, which the training data cannot tell apart: a
    friction region open to the joint's limit and the same one closed at the data's end), test it
    on the ``validation`` samples, Bonferroni over the families (and units); the candidates are
    independent, fitted and tested in ``options.jobs`` threads (same results). ``alongside``:
    candidates tested already on the same samples, whose families join the count (their fits and
    tests stand; their thresholds are those of the larger count), returned with the new ones."""
    exclude = exclude or {}
    tr = _Stack(res, weights, np.flatnonzero(train), exclude)
    va = _Stack(res, weights, np.flatnonzero(validation), exclude)
    best: dict[str, list[tuple[Candidate, _Fit]]] = {}
    eta = Eta(len(candidates))  # a long round says how far it is, with the time left
    fits = thread_imap(lambda c: _fit(c, tr, _candidate_channels(c)), candidates, options.jobs)
    for i, (cand, fit) in enumerate(zip(candidates, fits, strict=True)):
        key = cand.family or f"#{i}"
        if options.progress is not None and eta.due(i + 1):
            options.progress(f"candidate terms fitted: {eta.text(i + 1)}")
        if fit is None:
            continue
        if key not in best or fit.train_gain > best[key][0][1].train_gain:
            best[key] = [(cand, fit)]
        elif fit.train_gain == best[key][0][1].train_gain:
            best[key].append((cand, fit))
    before = {t.candidate.family or f"#before{i}" for i, t in enumerate(alongside)}
    n_tests = max(len(before | set(best)), 1) * max(options.n_units, 1)

    def judged(pair: tuple[Candidate, _Fit]) -> Tested:
        cand, fit = pair
        chans = _candidate_channels(cand)
        predicted = va.predicted(cand, fit.coef, chans)  # one pass over the validation rows
        test = _test(predicted, validation)
        thr = critical_t(options.alpha, n_tests, test.df)
        k = cand.n_params
        term = cand.term.with_linear_values(fit.coef[:k], fit.se)
        own, strongest, on_own = _own_gain(cand, predicted) if len(chans) > 1 else (None, None, None)
        gain = test.gain if own is None else max(own, test.gain)
        sig = bool(test.t > thr and gain >= options.min_gain)
        own_gain = None if own is None else gain
        return Tested(term, tuple(cand.columns), test, thr, sig, k, cand, own_gain, strongest, on_own,
                      _limit(cand, predicted, test, thr, weights, options.min_gain))

    def rejudged(t: Tested) -> Tested:
        thr = critical_t(options.alpha, n_tests, t.test.df)
        return replace(t, threshold=thr, significant=bool(t.test.t > thr and t.gain >= options.min_gain))

    out = [rejudged(t) for t in alongside]
    out += thread_map(judged, [pair for tied in best.values() for pair in tied], options.jobs)
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


#: A simpler candidate (fewer parameters, the same channels) that removes all but this share of
#: the validation error the best one removes is chosen instead: parameters that add less are not
#: worth a more complex cause, however precisely the difference is measured (arm3, a Coulomb
#: friction on joint3: a position friction over most of the range removed 82.9 % of the
#: validation error, the Coulomb friction 82.8 %, a difference of several standard errors).
SIMPLER_SHARE = 0.05


def choose(tested: list[Tested], validation: np.ndarray) -> Tested | None:
    """The significant candidate that removes the most validation error, or the simplest
    alternative to it (:func:`simplest`)."""
    sig = [t for t in tested if t.significant]
    if not sig:
        return None
    return simplest(max(sig, key=lambda t: t.test.sse_before - t.test.sse_after), tested, validation)


def simplest(best: Tested, tested: list[Tested], validation: np.ndarray) -> Tested:
    """``best``, unless a significant simpler candidate (fewer parameters, :attr:`Tested.dof`) on
    the same channels is within one standard error of it (paired over the validation sub-blocks
    of its test) or removes all but SIMPLER_SHARE of what it removes: then the simplest such (the
    one-SE rule, and practical significance)."""
    removed = best.test.sse_before - best.test.sse_after
    simpler = []
    for t in tested:
        if t is best or not t.significant or t.dof >= best.dof or set(t.channels) != set(best.channels):
            continue
        same_rows = np.isclose(t.test.sse_before, best.test.sse_before)  # its errors comparable
        if same_rows and t.test.sse_after - best.test.sse_after <= SIMPLER_SHARE * removed:
            simpler.append(t)
            continue
        mean, se, n = paired_difference(best.test.removed, t.test.removed, validation, best.test.length)
        if n >= 3 and mean <= se:  # the simpler one is worse by at most one standard error
            simpler.append(t)
    if simpler:
        return min(simpler, key=lambda t: (t.dof, t.test.sse_after))
    return best


#: Two candidates of one cause whose validation fits differ by less than this share of what the
#: chosen one removes are one finding to the data (:func:`indistinguishable`).
TWIN = 0.01
#: ... and so are two whose difference in what they remove, paired over the validation
#: sub-blocks, is within this many of its standard errors: a joint's origin moved along the
#: axis of the joint before it moves every link beyond alike, and a marker on the link between
#: takes up the rest (a blind iCub, r_elbow's origin moved 6 mm along the upper arm: on
#: r_shoulder_yaw it removed 2 % more of the validation error, within the noise).
TWIN_SE = 2.0


def indistinguishable(chosen: Tested, tested, validation: np.ndarray | None = None) -> list[str]:
    """The channels on which ``chosen``'s cause fits as well (:func:`_alike`): (nearly) the same
    columns, as a joint's offset along the axis of the joint before it is that joint's offset; the
    data cannot tell which channel it is, and the finding says so. With the ``validation`` mask,
    also a significant candidate of the cause on overlapping channels that removes as much to
    within TWIN_SE paired standard errors. A common candidate that holds the chosen channel
    (``joint2+joint3``) is no other channel: it fits as well by holding it."""
    key = (chosen.term.cause, chosen.term.channel)
    ref = next((t for t in tested if (t.term.cause, t.term.channel) == key), chosen)
    alike = _alike(ref, tested)
    if validation is not None:
        seen = {id(t) for t in alike}  # by identity: a Tested compares its arrays by value
        alike += [t for t in tested if id(t) not in seen and _removes_as_much(t, ref, validation)]
    return [t.term.channel for t in alike
            if t.term.cause == ref.term.cause and ref.term.channel not in t.term.channel.split("+")]


def _removes_as_much(t: Tested, ref: Tested, validation: np.ndarray, same_cause: bool = True) -> bool:
    """``t``, a significant candidate (of ``ref``'s cause unless not ``same_cause``) on channels
    overlapping ``ref``'s, removes the validation error ``ref`` removes to within TWIN_SE paired
    standard errors."""
    if t is ref or not t.significant or not set(t.channels) & set(ref.channels):
        return False
    if same_cause and t.term.cause != ref.term.cause:
        return False
    mean, se, n = paired_difference(ref.test.removed, t.test.removed, validation, ref.test.length)
    return n >= 3 and abs(mean) <= TWIN_SE * se


def rival_causes(chosen: Tested, tested, validation: np.ndarray | None = None) -> list[str]:
    """The significant terms of other causes that fit as well as ``chosen`` (:func:`_alike`: a
    torque offset and a spring on a joint whose angle never nears the spring's rest): the data
    cannot tell which cause it is, and the finding says so. With the ``validation`` mask, also one
    on overlapping channels (not a common cause) that removes as much, to within SIMPLER_SHARE of
    what ``chosen`` removes and within TWIN_SE paired standard errors (user
    trials: an offset named a spring with 1.1 % less removed; a spring near the arm's upright pose
    named a payload on the link beyond, which acts on more joints)."""
    alike = [t for t in _alike(chosen, tested) if t.significant and t.term.cause != chosen.term.cause]
    if validation is not None:
        seen, removed = {id(t) for t in alike}, chosen.test.sse_before - chosen.test.sse_after
        alike += [t for t in tested if id(t) not in seen and t.term.cause != chosen.term.cause
                  and "+" not in t.term.channel  # a common cause is one cause on several channels
                  and abs(t.test.sse_before - t.test.sse_after - removed) <= SIMPLER_SHARE * removed
                  and _removes_as_much(t, chosen, validation, same_cause=False)]
    return [t.term.label for t in alike]


def _alike(ref: Tested, tested) -> list:
    """The tested candidates that act on ``ref``'s residual channels and fit the validation data as
    well as it to within TWIN of what it removes."""
    removed = ref.test.sse_before - ref.test.sse_after
    if not removed > 0:
        return []
    return [
        t
        for t in tested
        if set(t.channels) == set(ref.channels)
        and np.isclose(t.test.sse_before, ref.test.sse_before)
        and abs(t.test.sse_after - ref.test.sse_after) <= TWIN * removed
    ]
