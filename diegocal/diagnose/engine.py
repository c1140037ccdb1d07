"""The diagnosis engine: show what a model gets wrong, name the cause, extend, measure the gain.

Domain-free. A domain supplies an :class:`Adapter` (``diagnose/dynamics.py``,
``diagnose/kinematics.py``, ``diagnose/pneumatics.py``) that fits its model with any extra terms,
gives the residuals per channel, proposes candidate terms as (linearised) regressor columns, and
scores a model on held-out samples. The engine owns the statistics and the order of the steps:
this module holds the data types and the loop (:func:`run_unit`); the fitting, testing and choice
of candidates is :mod:`.selection`, the evidence curves of a finding :mod:`.evidence`, the Show
step :mod:`.show`, the statistics :mod:`.stats`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from diegocal.diagnose.stats import OutOfSample
from diegocal.evaluate import Score
from diegocal.terms import Term


@dataclass(frozen=True)
class Residuals:
    """A model's residuals (measured − predicted) on every sample of the log, per channel.

    Attributes
    ----------
    channels : channel -> (T,) or (T, d) residual in the channel's unit; NaN where not measured
    units : channel -> unit ("N·m", "V", "m", "kPa")
    variables : name -> (T,) state variables to show the residuals against ("q.joint3", "u", ...)
    channel_variables : channel -> names of ``variables`` worth showing it against, most relevant first
    """

    channels: dict
    units: dict
    variables: dict = field(default_factory=dict)
    channel_variables: dict = field(default_factory=dict)


@dataclass(frozen=True)
class Candidate:
    """A term proposed for the model, linearised: residual ≈ Σ_channel columns @ θ.

    Attributes
    ----------
    term : the cause, channel, region and parameter names (values are not read)
    columns : residual channel -> (T, k) or (T, d, k): d(prediction)/d(θ) at θ = 0 on every sample
    family : variants of one family (the regions of one joint, the delays of one valve) share it;
        the engine keeps the variant with the best fit on the training samples, then tests it
    refit : residual channel -> (T, k0) or (T, d, k0): directions of the current model re-fitted
        together with the term (so that it does not merely take over a baseline term's part)
    """

    term: Term
    columns: dict
    family: str = ""
    refit: dict | None = None

    @property
    def n_params(self) -> int:
        return len(self.term.parameters)


@dataclass(frozen=True)
class Fault:
    """A per-reading data fault (marker outliers, swapped labels): not a regression.

    Attributes
    ----------
    term : the cause with ``extra`` naming what it found (frames, a swapped partner)
    readings : channel -> (T,) bool, the readings it explains
    exclude : True: those readings are left out of every score (an outlier predicts nothing);
        False: the term predicts them (a swap predicts the swapped readings)
    evidence : the detection's facts (threshold, readings, false-alarm rate)
    """

    term: Term
    readings: dict
    exclude: bool
    evidence: dict = field(default_factory=dict)


class Adapter(Protocol):
    """What a domain gives the engine (see the module docstring)."""

    domain: str
    unit_name: str

    def fit(self, terms: tuple[Term, ...], train: np.ndarray) -> Any: ...

    def residuals(self, fitted) -> Residuals: ...

    def candidates(self, fitted, residuals: Residuals, train: np.ndarray) -> list[Candidate]: ...

    def score(self, fitted, mask: np.ndarray, exclude: dict | None = None) -> Score: ...

    def terms(self, fitted) -> tuple[Term, ...]: ...

    def describe(self, fitted) -> str: ...

    def save(self, fitted, path, header: dict) -> Path: ...

    # Optional: ``absorb(fitted, channels, train) -> fitted | None``, the model extended with a
    # non-parametric part fitted on the training samples for the ``unexplained`` channels (the
    # dynamics SGP's GP); None when the domain has none. See :func:`run_unit`, step 3.


# ----------------------------------------------------------------------------- options and results
@dataclass(frozen=True)
class EngineOptions:
    """How strict the diagnosis is.

    alpha : family-wise false-alarm rate over every test of a log (Bonferroni across candidates,
        channels, rounds' candidates and units): clean data gives a finding with probability at
        most ``alpha`` from chance alone
    min_gain : practical significance: a finding must remove at least this fraction of the
        validation error of all its channels, or of its own channel when it names one it acts on
        most (a pot, a joint: where its held-out gain is measured, :meth:`Finding.gain`). A real
        but negligible model error is not worth a term; pooling a pot's term with every sensor its
        q projection touches dilutes it, and its own channel alone misses it where the pot fixes
        its joint's q (its in-sample residual follows it).
    unexplained_min_gain : the same for ``unexplained``: a binned correction spends ``n_bins``
        parameters on one channel where a term spends one to three, so it must pay more (on clean
        thin-plate chambers the 9-parameter model's known valve approximation leaves binned
        structure worth 5-12 % of the validation error)
    max_rounds : at most this many terms are added (the loop stops earlier when nothing is left)
    n_units : independent units diagnosed for the same log (chambers): alpha is shared among them
    n_bins : bins of a state variable in the Show step and the ``unexplained`` test
    progress : optional callable(str) told what the engine is doing
    """

    alpha: float = 0.01
    min_gain: float = 0.05
    unexplained_min_gain: float = 0.10
    max_rounds: int = 6
    n_units: int = 1
    n_bins: int = 10
    progress: Callable[[str], None] | None = None


@dataclass(frozen=True)
class Tested:
    """One candidate after fitting on the training rows and testing on the validation rows.

    term : the candidate's term with its training estimate (values, standard errors)
    channels : residual channels it acts on
    test : :class:`~diegocal.diagnose.stats.OutOfSample` on the validation rows
    threshold : the Bonferroni critical t it had to pass
    significant : t above the threshold and validation gain at least ``min_gain``
    channel_gain : the larger of the validation gains on the term's own channel (when it names
        one it acts on most) and on all its channels (None: it has no such channel)
    """

    term: Term
    channels: tuple[str, ...]
    test: OutOfSample
    threshold: float
    significant: bool
    n_params: int
    candidate: Candidate = field(repr=False)
    channel_gain: float | None = None

    @property
    def gain(self) -> float:
        """Fraction of the validation error removed: over all its channels, or on its own channel
        where it has one and that is larger."""
        return self.test.gain if self.channel_gain is None else self.channel_gain

    def to_dict(self) -> dict:
        return {
            "cause": self.term.cause,
            "channel": self.term.channel,
            "region": None if self.term.region is None else self.term.region.to_dict(),
            "validation_gain": round(float(self.gain), 4),
            "t": round(float(self.test.t), 2),
            "threshold_t": round(float(self.threshold), 2),
            "significant": bool(self.significant),
            "parameters": len(self.term.parameters),
        }


@dataclass(frozen=True)
class Finding:
    """What the diagnosis found: a term (``kind`` "term"), a data fault ("fault") or structure no
    candidate explains ("unexplained"), with its held-out gain and evidence."""

    term: Term
    kind: str
    heldout_before: Score | None
    heldout_after: Score | None
    evidence: dict = field(default_factory=dict)
    runners_up: tuple = ()

    @property
    def cause(self) -> str:
        return self.term.cause

    @property
    def channel(self) -> str:
        return self.term.channel

    def gain(self) -> dict:
        """Held-out RMSE before and after the finding: of its own channel where that is scored (a
        joint, a pot, a chamber), else pooled over the channels it acts on (a link's payload, a
        joint's offset seen by the markers)."""
        if self.heldout_before is None or self.heldout_after is None:
            return {}
        acts_on = self.evidence.get("channels", (self.channel,))
        own = self.evidence.get("own_channel", True)  # False: it acts mostly elsewhere (a joint's namesake pot)
        if own and self.channel in self.heldout_before.channels and self.channel in acts_on:
            chans = [self.channel]
        else:
            chans = [c for c in self.evidence.get("channels", ()) if c in self.heldout_before.channels]
        before = _pooled(self.heldout_before, chans)
        after = _pooled(self.heldout_after, chans)
        red = 1.0 - after / before if before > 0 and np.isfinite(before) and np.isfinite(after) else float("nan")
        return {"rmse_before": before, "rmse_after": after, "reduction": red}


@dataclass(frozen=True)
class UnitDiagnosis:
    """The diagnosis of one unit (a robot, a chamber)."""

    unit: str
    domain: str
    baseline_model: str
    baseline_score: Score
    extended_model: str
    extended_score: Score
    findings: tuple[Finding, ...]
    show: dict
    fitted: Any = field(repr=False, default=None)
    exclude: dict = field(repr=False, default_factory=dict)
    units: dict = field(default_factory=dict)  # channel -> unit ("V", "m", "N·m", "kPa")


def _pooled(score: Score, channels) -> float:
    idx = [score.channels.index(c) for c in channels if c in score.channels]
    if not idx:
        return float("nan")
    n = score.n_samples[idx].astype(float)
    r = score.rmse[idx]
    ok = (n > 0) & np.isfinite(r)
    if not ok.any():
        return float("nan")
    return float(np.sqrt(np.sum(r[ok] ** 2 * n[ok]) / n[ok].sum()))


# ----------------------------------------------------------------------------- the loop
def run_unit(adapter: Adapter, blocks, options: EngineOptions | None = None) -> UnitDiagnosis:
    """Diagnose one unit (DESIGN.md "Diagnosis output"; the module docstring; issue #13's steps):

    1. Show: fit the baseline on the training blocks; residuals on every sample; the Show step.
    2. Name the cause: data faults first (a fault corrupts every fit), then rounds of candidates,
       each fitted on the training blocks and tested on the validation blocks; the winner's term
       is added and the model refitted, until no candidate is significant (or ``max_rounds``).
       What stays significant in the binned test is ``unexplained``.
    3. Extend: the last fit is the extended model (``adapter.save`` writes it). Where something
       stays ``unexplained`` and the adapter has ``absorb``, its non-parametric part is fitted on
       the training blocks and kept if it lowers the validation error of those channels (the
       blocks that chose the terms; the held-out blocks stay unseen).
    4. Measure the gain: held-out blocks only, never used to select.
    """
    from diegocal.diagnose.evidence import curves, evidence_variable
    from diegocal.diagnose.selection import channel_weights, choose, evaluate_candidates
    from diegocal.diagnose.show import binned_candidate, region_of, show
    from diegocal.diagnose.stats import cluster_length

    options = options or EngineOptions()
    say = options.progress or (lambda text: None)
    train, val, held = blocks.mask("train"), blocks.mask("validation"), blocks.mask("heldout")
    unit = f" {adapter.unit_name}" if getattr(adapter, "unit_name", "") else ""
    say(f"fitting the baseline{unit} on {int(train.sum())} training samples")
    fitted = adapter.fit((), train)
    baseline = fitted
    res = adapter.residuals(fitted)
    weights = channel_weights(res, train)
    length = cluster_length([np.asarray(r, float)[train] for r in res.channels.values()])
    shown = val | held
    time = res.variables.get("time")
    say(f"Show step{unit}: {len(res.channels)} channels")
    shown_tests = show(res, weights, train, val, shown, length, options, time)
    exclude: dict = {}
    findings: list[Finding] = []
    terms: tuple[Term, ...] = ()

    faults = getattr(adapter, "faults", None)
    for fault in faults(fitted, res) if faults else []:
        if fault.exclude:
            for c, m in fault.readings.items():
                exclude[c] = np.asarray(exclude.get(c, np.zeros_like(m, bool)), bool) | np.asarray(m, bool)
        new = adapter.fit(terms + (fault.term,), train)
        before, after = adapter.score(fitted, held, exclude), adapter.score(new, held, exclude)
        evidence = dict(fault.evidence, channels=list(fault.readings))
        findings.append(Finding(fault.term, "fault", before, after, evidence))
        fitted, terms = new, adapter.terms(new)
        say(f"found {fault.term.cause} on {fault.term.channel}{unit}")

    for _ in range(options.max_rounds):
        res = adapter.residuals(fitted)
        candidates = adapter.candidates(fitted, res, train)
        say(f"testing {len(candidates)} candidate terms{unit}")
        tested = evaluate_candidates(candidates, res, weights, train, val, options, exclude)
        best = choose(tested, val)
        if best is None:
            break
        new = adapter.fit(terms + (best.term,), train)
        before, after = adapter.score(fitted, held, exclude), adapter.score(new, held, exclude)
        res_new = adapter.residuals(new)
        variable = evidence_variable(best.term, res)
        evidence = {
            "channels": list(best.channels),
            "validation_gain": float(best.gain),
            "own_channel": best.channel_gain is not None or len(best.channels) == 1,
            "t": float(best.test.t),
            "threshold_t": float(best.threshold),
            "variable": variable,
        }
        if variable is not None:
            evidence["curves"] = curves(
                res, res_new, best.channels[0], variable, shown, length, train, options.n_bins, exclude
            )
        runners = tuple(t.to_dict() for t in tested if t is not best)[:8]
        new_terms = adapter.terms(new)
        fitted_term = next((t for t in new_terms if _same(t, best.term)), best.term)
        findings.append(Finding(fitted_term, "term", before, after, evidence, runners))
        fitted, terms = new, new_terms
        say(f"found {best.term.cause} on {best.term.channel}{unit} (validation gain {best.gain:.0%})")

    # what remains: significant binned structure that no candidate explained
    res = adapter.residuals(fitted)
    generic = [
        binned_candidate(res, c, v, train, options.n_bins)
        for c in res.channels
        for v in res.channel_variables.get(c, ())
    ]
    if generic:
        strict = replace(options, min_gain=max(options.min_gain, options.unexplained_min_gain))
        tested = evaluate_candidates(generic, res, weights, train, val, strict, exclude)
        for t in [t for t in tested if t.significant]:
            if any(f.kind == "unexplained" and f.channel == t.term.channel for f in findings):
                continue  # one per channel: its most significant variable
            region = region_of(t)
            term = Term("unexplained", t.term.channel, (), region)
            evidence = {
                "channels": list(t.channels),
                "validation_gain": float(t.gain),
                "t": float(t.test.t),
                "threshold_t": float(t.threshold),
                "variable": region.variable,
            }
            evidence["curves"] = curves(
                res, None, t.term.channel, region.variable, shown, length, train, options.n_bins, exclude
            )
            findings.append(Finding(term, "unexplained", None, None, evidence))
            say(f"unexplained structure on {t.term.channel}{unit} against {region.variable}")
    absorbed, findings = _absorb(adapter, fitted, findings, (train, val, held), exclude, options, unit)
    if absorbed is not fitted:  # the evidence plots of what it absorbed: before and after
        res_new = adapter.residuals(absorbed)
        findings = [
            replace(
                f,
                evidence={
                    **f.evidence,
                    "curves": curves(
                        res, res_new, f.channel, f.evidence["variable"], shown, length, train, options.n_bins, exclude
                    ),
                },
            )
            if f.kind == "unexplained"
            else f
            for f in findings
        ]
        fitted = absorbed

    baseline_score = adapter.score(baseline, held, exclude)
    extended_score = adapter.score(fitted, held, exclude)
    return UnitDiagnosis(
        getattr(adapter, "unit_name", ""),
        adapter.domain,
        adapter.describe(baseline),
        baseline_score,
        adapter.describe(fitted),
        extended_score,
        tuple(findings),
        shown_tests,
        fitted,
        exclude,
        dict(res.units),
    )


def _absorb(adapter, fitted, findings, masks, exclude, options: EngineOptions, unit: str):
    """Step 3 for what stays ``unexplained``: the adapter's non-parametric extension (``absorb``),
    kept when it removes at least ``min_gain`` of the validation mean squared error pooled over
    the unexplained channels (as a term must); each unexplained finding then gets its held-out
    RMSE before → after and the evidence ``nonparametric``. ``masks``: train, validation, held out."""
    train, val, held = masks
    say = options.progress or (lambda text: None)
    absorb = getattr(adapter, "absorb", None)
    channels = tuple(dict.fromkeys(f.channel for f in findings if f.kind == "unexplained"))
    if absorb is None or not channels:
        return fitted, findings
    say(f"fitting the non-parametric part{unit} for {', '.join(channels)}")
    new = absorb(fitted, channels, train)
    if new is None:
        return fitted, findings
    before, after = (
        _pooled(adapter.score(fitted, val, exclude), channels),
        _pooled(adapter.score(new, val, exclude), channels),
    )
    kept = bool(np.isfinite(after) and after**2 <= (1.0 - options.min_gain) * before**2)
    note = {
        "model": adapter.describe(new),
        "validation_rmse_before": before,
        "validation_rmse_after": after,
        "kept": kept,
    }
    if kept:
        hb, ha = adapter.score(fitted, held, exclude), adapter.score(new, held, exclude)
    out = []
    for f in findings:
        if f.kind == "unexplained":
            f = replace(f, evidence={**f.evidence, "nonparametric": note})
            if kept:
                f = replace(f, heldout_before=hb, heldout_after=ha)
        out.append(f)
    say(f"non-parametric part {'kept' if kept else 'dropped'}{unit}: validation RMSE {before:.4g} → {after:.4g}")
    return (new if kept else fitted), out


def _same(a: Term, b: Term) -> bool:
    return a.cause == b.cause and a.channel == b.channel and a.region == b.region
