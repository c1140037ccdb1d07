"""The diagnosis engine's data: residuals, candidate terms, faults, findings and options.

Shared by the engine (:mod:`.engine`), the choice of candidates (:mod:`.selection`), the Show step
(:mod:`.show`), a finding's evidence (:mod:`.evidence`) and each domain's adapter, so that those
modules import in one direction only.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
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
    context : channel -> further ``variables`` its error may depend on through no term of the
        vocabulary (the other joints' angles: a hose pulled by the next link); the flexible model a
        named term is measured against uses them too (:func:`~diegocal.diagnose.show.flexible_candidate`)
    """

    channels: dict
    units: dict
    variables: dict = field(default_factory=dict)
    channel_variables: dict = field(default_factory=dict)
    context: dict = field(default_factory=dict)


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
    members : for one cause on several channels tested as one (:func:`~diegocal.diagnose.
        selection.common_candidates`), the tested candidates it joins; () otherwise
    visible : the share of the term's own columns' norm that ``columns`` keep, where the adapter
        projected the model's span out of them (1: not projected): an effect of RMS e leaves
        about visible × e to test, so its detection limit is the correction's over it
    """

    term: Term
    columns: dict
    family: str = ""
    refit: dict | None = None
    members: tuple = ()
    visible: float = 1.0

    @property
    def n_params(self) -> int:
        """Its columns' count: the term's linear parameters (a shape parameter is held)."""
        return len(self.term.linear)


def column_rows(columns, channel: str, samples):
    """A candidate's columns of ``channel`` on ``samples`` (None where it has none there): those
    rows alone, from a columns mapping that builds them itself (``rows``: binned and joined
    columns, which never build all T) or by indexing the channel's array."""
    if not columns or channel not in columns:
        return None
    if hasattr(columns, "rows"):
        return columns.rows(channel, samples)
    x = columns[channel]
    return None if x is None else x[samples]


def fitted_form(term: Term, fitted_terms) -> Term:
    """``term`` as a fit of it left it among ``fitted_terms`` (its values refined, with standard
    errors; its region and shape may have moved): the one of the same cause on the same channel
    (and partner), or ``term`` itself where the fit has none."""
    key = (term.cause, term.channel, term.extra.get("partner"))
    return next((t for t in fitted_terms if (t.cause, t.channel, t.extra.get("partner")) == key), term)


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
    # Optional: ``restate(fitted, term) -> (fitted, term, why) | None``, the fit with another cause
    # for a fitted term whose values its own cause cannot have (a payload no body can be: ``link_inertia``).


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
        its joint's q (its in-sample residual follows it). A term, once added, and a fault must
        remove as much of the held-out mean squared error (:func:`~diegocal.diagnose.engine.run_unit`).
    unexplained_min_gain : the same for ``unexplained``: a binned correction spends ``n_bins``
        parameters on one channel where a term spends one to three, so it must pay more (on clean
        thin-plate chambers the 9-parameter model's known valve approximation leaves binned
        structure worth 5-12 % of the validation error)
    max_rounds : at most this many terms are added (the loop stops earlier when nothing is left)
    n_units : independent units diagnosed for the same log (chambers): alpha is shared among them
    n_bins : bins of a state variable in the Show step and the ``unexplained`` test
    progress : optional callable(str) told what the engine is doing
    jobs : threads fitting and testing a round's candidates (one unit's: the units of a log are
        spread over processes instead)
    """

    alpha: float = 0.01
    min_gain: float = 0.05
    unexplained_min_gain: float = 0.10
    max_rounds: int = 6
    n_units: int = 1
    n_bins: int = 10
    progress: Callable[[str], None] | None = None
    jobs: int = 1


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
    strongest : (channel, validation gain there) of the channel the correction acts on most, for a
        term on several channels that names none of them (a payload on a link); None otherwise
    own_gain : the validation gain on the term's own channel, for a term on several channels that
        names one of them, whichever it acts on most (None otherwise)
    detectable : (channel, RMS in its unit, over its residual RMS, the bar that sets it) of the
        smallest effect shaped like the correction that is found 80 % of the time, on the term's
        own channel or the one it acts on most (:mod:`.limits`); None where not computed
    """

    term: Term
    channels: tuple[str, ...]
    test: OutOfSample
    threshold: float
    significant: bool
    n_params: int
    candidate: Candidate = field(repr=False)
    channel_gain: float | None = None
    strongest: tuple | None = None
    own_gain: float | None = None
    detectable: tuple | None = None

    @property
    def dof(self) -> int:
        """What the fit that adds it adjusts: its columns' coefficients and its shape parameters (a
        spring's rest angle, which makes a spring whose rest lies far off a torque offset); a
        cause tested on several channels at once, its members' together."""
        if self.candidate.members:
            return sum(m.dof for m in self.candidate.members)
        return self.n_params + len(self.term.parameters) - len(self.term.linear)

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
        else:  # the channels of one unit it acts on (files of older diagnoses: every channel)
            pool = self.evidence.get("gain_channels") or self.evidence.get("channels", ())
            chans = [c for c in pool if c in self.heldout_before.channels]
        before = pooled(self.heldout_before, chans)
        after = pooled(self.heldout_after, chans)
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
    minor_faults: tuple[Finding, ...] = ()  # detected, writing-off removed under min_gain (evidence.written_off)
    unconverged: tuple[str, ...] = ()  # the baseline's and the kept fits' stops at a cap, in words
    declined: tuple[dict, ...] = ()  # significant terms not added: {cause, channel, why}, why in words
    detection_limits: tuple[dict, ...] = ()  # what it could not have seen (:mod:`.limits`), least detectable first


def pooled(score: Score, channels) -> float:
    """RMSE pooled over ``channels`` of a score (samples-weighted; NaN without any)."""
    idx = [score.channels.index(c) for c in channels if c in score.channels]
    if not idx:
        return float("nan")
    n = score.n_samples[idx].astype(float)
    r = score.rmse[idx]
    ok = (n > 0) & np.isfinite(r)
    if not ok.any():
        return float("nan")
    return float(np.sqrt(np.sum(r[ok] ** 2 * n[ok]) / n[ok].sum()))
