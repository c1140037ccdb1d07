"""The diagnosis engine: show what a model gets wrong, name the cause, extend, measure the gain.

Domain-free. A domain supplies an :class:`Adapter` (``diagnose/dynamics.py``,
``diagnose/kinematics.py``, ``diagnose/pneumatics.py``) that fits its model with any extra terms,
gives the residuals per channel, proposes candidate terms as (linearised) regressor columns, and
scores a model on held-out samples. The engine owns the statistics and the order of the steps:
:mod:`.types` holds the data types, this module the loop (:func:`run_unit`); the fitting, testing
and choice of candidates is :mod:`.selection`, the evidence curves of a finding :mod:`.evidence`, the Show
step :mod:`.show`, the statistics :mod:`.stats`.
"""

from __future__ import annotations

from dataclasses import replace
from functools import partial

import numpy as np

from diegocal.causes import search_end, unphysical
from diegocal.diagnose.evidence import curves, direction, evidence_variable
from diegocal.diagnose.faults import heldout_removed, write_off
from diegocal.diagnose.limits import detection_limits, unseen
from diegocal.diagnose.selection import (
    channel_weights,
    choose,
    common_candidates,
    evaluate_candidates,
    indistinguishable,
    rival_causes,
    simplest,
)
from diegocal.diagnose.show import binned_candidate, show, unexplained_region
from diegocal.diagnose.stand_ins import (
    declined_evidence,
    declined_rival,
    members_kept,
    outshone,
    own_channel,
    refit_rival,
    same_cause_beside,
    searched_out,
    spilled,
    stand_in_finding,
)
from diegocal.diagnose.stats import cluster_length
from diegocal.diagnose.types import (
    Adapter,
    Candidate,
    EngineOptions,
    Fault,
    Finding,
    Residuals,
    Tested,
    UnitDiagnosis,
    fitted_form,
    pooled,
)
from diegocal.terms import Term

__all__ = [
    "Adapter",
    "Candidate",
    "EngineOptions",
    "Fault",
    "Finding",
    "Residuals",
    "Tested",
    "UnitDiagnosis",
    "run_unit",
]


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
    4. Measure the gain: held-out blocks only, never used to choose between candidates. A term
       is declined (listed among the runners-up, with why) when, added, the data do not determine
       it (every coefficient within 2 standard errors of 0) or the held-out error rises: a
       validation test on a few clusters (a static-pose log's poses) can pass by chance. A fault
       is a finding only when writing it off removes at least ``min_gain`` of the held-out mean
       squared error (the bar a term's validation gain must clear): a detector flags a few
       readings of any log, and leaving out readings that were not faulty changes next to
       nothing. A minor fault (under that bar) is still written off unless that raises the
       held-out error (a swap of two labels in the training blocks barely moves the fit, yet its
       frames make a common backlash significant) and is said apart (``minor_faults``). A time
       region whose edge falls between training blocks (a slip inside a held-out block) has its
       gain measured outside that span (:func:`unplaced_span`).
    """
    options = options or EngineOptions()
    say = options.progress or (lambda text: None)
    if hasattr(adapter, "progress"):  # an adapter whose passes over a long log take long says how far
        adapter.progress = options.progress
    train, val, held = blocks.mask("train"), blocks.mask("validation"), blocks.mask("heldout")
    unit = f" {adapter.unit_name}" if getattr(adapter, "unit_name", "") else ""
    say(f"fitting the baseline{unit} on {int(train.sum())} training samples")
    fitted = baseline = adapter.fit((), train)
    late = getattr(adapter, "unconverged", lambda _: ())  # what a fit left at a cap, in words
    unconverged = dict.fromkeys(f"baseline: {why}" for why in late(baseline))
    res = adapter.residuals(fitted)
    weights = channel_weights(res, train)
    if hasattr(adapter, "selection_weights"):  # an adapter that proposes each family's best variant ranks them so
        adapter.selection_weights = weights
    length = cluster_length([np.asarray(r, float)[train] for r in res.channels.values()])
    shown = val | held
    time = res.variables.get("time")
    say(f"residuals of the baseline{unit}: {len(res.channels)} channels, each against its state")
    shown_tests = show(res, weights, train, val, shown, length, options, time)
    fitted, terms, exclude, findings, minor = write_off(adapter, fitted, res, train, held, options, say, unit)
    if fitted is not baseline:
        unconverged.update(dict.fromkeys(f"with the faults written off: {why}" for why in late(fitted)))
    if hasattr(adapter, "selection_exclude"):  # (as selection_weights) the readings the selection leaves out
        adapter.selection_exclude = exclude
    stand_ins: dict = {}  # channel -> (the term that stood in, the test that beat it, its evidence or None)
    pending: dict = {}  # a common cause's member that stood in: channel -> (as stand_ins, findings made then)
    limits = ()  # what the last round could not have seen
    declined: dict = {}  # (cause, channel) -> why, in words: significant, but no held-out gain
    spill = getattr(adapter, "spill_candidates", None)  # flexible curves of a term's neighbours
    rival = getattr(adapter, "shape_rival", None)  # a model of another shape, judged on the adapter's own score
    refits = getattr(adapter, "refit_rivals", False)  # a term judged on several channels against its channel's rival
    for _ in range(options.max_rounds):
        # the last round's columns go before this round's are built (a tested candidate's columns
        # are views of its round's whole block: one kept Tested keeps all of them)
        candidates = tested = commons = best = group = chosen = None
        res = adapter.residuals(fitted)
        say(f"proposing candidate terms{unit}")
        candidates = adapter.candidates(fitted, res, train)
        say(f"testing {len(candidates)} candidate terms{unit}")
        tested = evaluate_candidates(candidates, res, weights, train, val, options, exclude)
        commons = common_candidates(tested)
        if commons:  # the common causes beside the winners: one family-wise rate for all
            tested = evaluate_candidates(commons, res, weights, train, val, options, exclude, alongside=tested)
        limits = detection_limits(tested, res.units, getattr(adapter, "in_span", ()))  # the last round's
        tested = [t for t in tested if not set(t.channels) & set(stand_ins)]
        tested = [replace(t, significant=False) if _key(t.term) in declined else t for t in tested]
        neighbours = None if spill is None else partial(spill, fitted, train)
        shape = None if rival is None else partial(rival, fitted, train, val, options, exclude)
        refit = partial(refit_rival, adapter, terms, (train, val), weights, exclude) if refits else None
        stood: dict = {}
        best, group, tested = _choose_group(
            tested, res, weights, train, val, options, exclude, stand_ins, say, unit, neighbours, declined, shape,
            refit, stood,
        )
        pending |= {c: (s, len(findings)) for c, s in stood.items() if c not in pending}
        group = [g for g in group if _key(g.term) not in declined]
        candidates = commons = None  # what follows needs the tested terms, not their columns:
        best, group, tested = _without_columns(best, group, tested)  # the refits run without them
        if not group:
            break
        for chosen in group:
            new, term, restated = _restate(adapter, adapter.fit(terms + (chosen.term,), train), chosen.term)
            unplaced = unplaced_span(chosen.term, time, train)
            scored = held if unplaced is None else held & ~unplaced
            before, after = adapter.score(fitted, scored, exclude), adapter.score(new, scored, exclude)
            res_new = adapter.residuals(new)
            primary = own_channel(chosen)  # its own channel, else the one it acts on most
            variable = evidence_variable(chosen.term, res, primary)
            evidence = {
                "channels": list(chosen.channels),
                # the gain pools the channels of one unit: volts and metres are not added
                "gain_channels": [c for c in chosen.channels if res.units.get(c) == res.units.get(primary)],
                "validation_gain": float(chosen.gain),
                "own_channel": chosen.channel_gain is not None or len(chosen.channels) == 1,
                "t": float(chosen.test.t),
                "threshold_t": float(chosen.threshold),
                "variable": variable,
            }
            if restated:
                evidence["restated"] = restated
            twins = indistinguishable(chosen, tested, val)
            if twins:
                evidence["indistinguishable_from"] = twins
            if rivals := rival_causes(chosen, tested, val):
                evidence["indistinguishable_causes"] = rivals
            if unplaced is not None and (held & unplaced).any():
                edges = time[np.flatnonzero(unplaced)[[0, -1]]]
                evidence["heldout_leaves_out"] = [float(edges[0]), float(edges[1])]
            if chosen is not best:
                evidence["common_cause"] = (
                    f"{best.term.cause} on {best.term.channel}, tested as one: t {best.test.t:.1f} "
                    f"(threshold {best.threshold:.1f}), validation gain {best.test.gain:.0%}"
                    if best.candidate.members
                    else f"added with {best.term.label} in one round: the same cause"
                )
            if variable is not None:
                signed_by, partner = direction(chosen.term)  # friction: the residual times sign(qd)
                evidence["curves"] = curves(
                    res, res_new, primary, variable, shown, length, train, options.n_bins, exclude, signed_by, partner
                )
            added = {_key(g.term) for g in group} | {_key(best.term)}
            runners = tuple(_runner_up(t, chosen, declined, term.cause, rivals) for t in tested
                            if _key(t.term) not in added)
            runners = runners[:8]
            new_terms = adapter.terms(new)
            fitted_term = fitted_form(term, new_terms)
            finding = Finding(fitted_term, "term", before, after, evidence, runners)
            why = _decline(finding, options.min_gain)
            if why:
                declined[_key(chosen.term)] = why
                if (entry := searched_out(fitted_term, chosen, why)) is not None:  # its structure stays: unexplained
                    stand_ins.setdefault(primary, entry)
                say(f"{term.cause} on {_where(term.channel, unit)}: {why}; declined")
                continue
            findings.append(finding)
            fitted, terms = new, new_terms
            unconverged.update(dict.fromkeys(f"with {fitted_term.label}: {why}" for why in late(new)))
            say(f"found {term.cause} on {_where(term.channel, unit)} (validation gain {chosen.gain:.0%})")

    candidates = tested = commons = best = group = chosen = None  # the last round's columns
    for channel, (entry, made) in pending.items():  # unexplained unless a later finding took up its channel
        if channel not in stand_ins and not any(channel in f.evidence.get("channels", ()) for f in findings[made:]):
            stand_ins[channel] = entry
    # each finding's values as the last fit, with every term, left them (a later term moves them)
    findings = [replace(f, term=fitted_form(f.term, terms)) if f.kind == "term" else f for f in findings]
    getattr(adapter, "release", lambda: None)()  # and what the adapter kept for its rounds
    # what remains: the channels whose best term was a stand-in, then significant binned
    # structure that no candidate explained
    res = adapter.residuals(fitted)
    for channel, (stood, flex, why) in stand_ins.items():
        masks = (train, val, shown)
        findings.append(stand_in_finding(channel, stood, flex, res, weights, masks, length, options, exclude, why))
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
            region = unexplained_region(t)
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
            say(f"unexplained structure on {_where(t.term.channel, unit)} against {region.variable}")
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
        unconverged.update(dict.fromkeys(f"with the non-parametric part: {why}" for why in late(absorbed)))

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
        tuple(minor),
        tuple(unconverged),
        tuple({"cause": cause, "channel": channel, "why": why} for (cause, channel), why in declined.items()),
        unseen(limits, findings),
    )


def _absorb(adapter, fitted, findings, masks, exclude, options: EngineOptions, unit: str):
    """Step 3 for what stays ``unexplained``: the adapter's non-parametric extension (``absorb``),
    kept when it removes at least ``min_gain`` of the validation mean squared error pooled over
    the unexplained channels (as a term must) and raises the other channels' pooled one by no
    more than that fraction; each
    unexplained finding then gets its held-out RMSE before → after and the evidence
    ``nonparametric``. ``masks``: train, validation, held out."""
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
    score_before, score_after = adapter.score(fitted, val, exclude), adapter.score(new, val, exclude)
    before, after = pooled(score_before, channels), pooled(score_after, channels)
    others = [c for c in score_before.channels if c not in channels]
    # the others may move by noise, not by more than a term must gain
    spoilt = (
        bool(others)
        and not pooled(score_after, others) ** 2 <= (1.0 + options.min_gain) * pooled(score_before, others) ** 2
    )
    kept = bool(np.isfinite(after) and after**2 <= (1.0 - options.min_gain) * before**2 and not spoilt)
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


def _choose_group(
    tested, res, weights, train, val, options, exclude, stand_ins, say, unit, neighbours=None, declined=(), shape=None,
    refit=None, stood=None,
) -> tuple:
    """(the best candidate, the terms this round adds, the candidates left in the running and those a
    rival beat once both were refitted, in the order tested): the
    best and the other channels of its cause (no terms when nothing is significant). A best term
    that its channel's state explains far better stands in for structure of another shape: its
    channel goes to ``stand_ins`` (left unexplained) and the next best is chosen; so does the
    channel of a neighbour whose own flexible model explains more than the term (:func:`~.stand_ins.spilled`;
    ``neighbours(term, channels)``: the adapter's ``spill_candidates``), that of a term a declined
    one (``declined``) explained better (:func:`~.stand_ins.declined_rival`), and that of a term a
    model of another shape beats on the adapter's own score (``shape(term)``: the adapter's
    ``shape_rival``, (the rival as tested, its evidence) or None; a chamber's pressure read through
    a filter, :mod:`.pneumatics_filter`). A best term that a rival of its channel judged on fewer
    channels beats once both are refitted (``refit(best, tested)``: :func:`~.stand_ins.refit_rival`,
    for an adapter with ``refit_rivals``) is declined, and the next best chosen. A common cause whose channels
    have no evidence of their own is dropped, and so is one whose evidence is one channel's where a
    simpler cause does as well (:func:`~.selection.simplest`). A member or a same-cause term that
    stands in goes to ``stood`` (its channel ``unexplained`` at the end unless a later round's
    finding takes it up: a spring on joint1 beside one on joint2 stood in for a torque offset
    named on joint1 the round after)."""
    beaten, everyone = [], tested  # beaten: best terms a rival beat when both were refitted

    def left():  # the candidates left in the running and the beaten ones, in the order tested
        kept = {id(t) for t in (*tested, *beaten)}
        return [t for t in everyone if id(t) in kept]

    while (best := choose(tested, val)) is not None:
        if best.candidate.members:  # one cause on several channels: each channel's term
            group = members_kept(best, tested, declined, res, weights, train, val, options, exclude, stood, neighbours)
            if len(group) == 1 and simplest(group[0], tested, val) is not group[0]:
                group = []  # its evidence is one channel's, where a simpler cause does as well
            if group:
                return best, group, left()
            tested = [t for t in tested if t is not best]
            continue
        own = own_channel(best)
        flex = outshone(best, res, weights, train, val, options, exclude, tested)
        why, evidence = "its state does", None
        if flex is None and neighbours is not None:
            flex = spilled(best, neighbours(best.term, best.channels), res, weights, train, val, options, exclude)
            if flex is not None:
                own, why = flex.term.channel, f"a flexible model of {flex.term.channel} does"
        if flex is None and (flex := declined_rival(best, tested, declined)) is not None:
            why = f"{flex.term.cause} (declined) did"
            evidence = declined_evidence(flex, declined)
        if flex is None and shape is not None and (found := shape(best.term)) is not None:
            flex, rival = found
            why, evidence = f"{rival['model']} does", {"rival": rival}
        if flex is None and refit is not None and (found := refit(best, tested)) is not None:
            declined[_key(best.term)] = found[1]  # the rival's channel's best judged next
            say(f"{best.term.cause} on {_where(best.term.channel, unit)}: {found[1]}; declined")
            tested, beaten = [t for t in tested if t is not best], [*beaten, best]  # a runner-up, with why
            continue
        if flex is None:
            commons = same_cause_beside(
                best, tested, declined, res, weights, train, val, options, exclude, stood, neighbours
            )
            return best, [best, *commons], left()
        stand_in = (replace(best, candidate=None), replace(flex, candidate=None), evidence)  # no columns kept
        stand_ins.setdefault(own, stand_in)
        say(f"{best.term.cause} on {_where(best.term.channel, unit)} explains less than {why}: {own} left unexplained")
        tested = [t for t in tested if t is not best and own not in t.channels]
    return None, [], left()


def _where(channel: str, unit: str) -> str:
    """Where a progress line's term acts: its channel, and the unit (`` name``) in brackets when
    that is not the channel itself (a chamber is both): "joint_6 (staubli_tx40)"."""
    return channel if unit.strip() in ("", channel) else f"{channel} ({unit.strip()})"


def _key(term: Term) -> tuple[str, str]:
    return term.cause, term.channel


#: A fitted coefficient is determined by the data when it is at least this many standard errors
#: from 0 (about a 5 % two-sided level).
DETERMINED_Z = 2.0


def unplaced_span(term: Term, time, train: np.ndarray) -> np.ndarray | None:
    """(T,) bool, the samples between the training samples either side of a time region's edge
    (a slip's start), or None: the fit puts the edge somewhere in that span without data to place
    it (a slip inside a held-out block starts in its middle), so the finding's held-out gain is
    measured outside it; the extended model's held-out score keeps every sample."""
    region = term.region
    if region is None or region.variable != "time" or time is None:
        return None
    time = np.asarray(time, float)
    out = np.zeros(time.size, bool)
    for edge in (region.low, region.high):
        if not np.isfinite(edge):
            continue
        before, after = np.flatnonzero(train & (time < edge)), np.flatnonzero(train & (time >= edge))
        out[(before[-1] + 1 if before.size else 0) : (after[0] if after.size else time.size)] = True
    return out if out.any() else None


def _restate(adapter: Adapter, new, term: Term):
    """The fit with ``term`` (``new``) as its fitted values name it (the adapter's ``restate``: a
    payload no body can be is ``link_inertia``); the fit, its term, why ("": as it was)."""
    got = getattr(adapter, "restate", lambda f, t: None)(new, fitted_form(term, adapter.terms(new)))
    return (new, term, "") if got is None else got


def _decline(finding: Finding, min_gain: float) -> str:
    """Why a significant term is not a finding after all, in words ("" when it is one): its
    coefficients are all within DETERMINED_Z standard errors of 0 (unknown standard errors
    excepted; not judged when one is not fixed alone: a combination of them may be), the
    held-out error rose when it was added, or it removed under ``min_gain`` of the held-out mean
    squared error: the bar its validation gain cleared, and a fault's (a pot's
    drift or a sibling pot's anomaly gives a backlash that pays on validation, not held out); or a
    parameter ends at the upper end of its search (the registry's bound: a torque sensor's lag of
    0.5 s), where the data want more than the cause describes (its channel is then ``unexplained``:
    :func:`~.stand_ins.searched_out`), or one that cannot be negative (a friction, an inertia, a
    mass) is significantly so: it would stand in for something else."""
    for p in finding.term.parameters:
        if (spec := search_end(finding.term.cause, p.name, p.value)) is not None:
            end = f"{spec.upper:g} {p.unit or spec.unit}"
            return f"its {p.name} ends at the end of its search ({end}): the data want more"
        if (spec := unphysical(finding.term.cause, p.name, p.value, p.stderr, DETERMINED_Z)) is not None:
            return (f"its {p.name} is negative ({p.value:.3g} ± {p.stderr:.2g} {p.unit or spec.unit}), which "
                    f"{finding.term.cause} cannot be: it stands in for something else")
    coef = [(p.value, p.stderr) for p in finding.term.linear if np.isfinite(p.stderr) and p.stderr > 0]
    # a coefficient the data do not fix alone (infinite SE) may belong to a combination they do fix
    unfixed = any(np.isinf(p.stderr) for p in finding.term.linear)
    if coef and not unfixed and all(abs(v) < DETERMINED_Z * se for v, se in coef):
        return f"the data do not determine it (every coefficient within {DETERMINED_Z:g} standard errors of 0)"
    red = finding.gain().get("reduction", float("nan"))
    if np.isfinite(red) and red < 0:
        return f"significant on validation, but the held-out error rose by {-red:.1%} with it"
    removed = heldout_removed(finding)
    if removed < min_gain:
        return f"significant on validation, but it removes {removed:.1%} of the held-out error (under {min_gain:.0%})"
    return ""


def _runner_up(t: Tested, best: Tested, declined: dict, named: str = "", rivals=()) -> dict:
    """A tested candidate that was not added, with why, in words, when it was significant (or
    declined for having no held-out gain); ``named``: the cause ``best`` was added as (its own
    unless restated); ``rivals``: the labels of the causes the data cannot tell from it."""
    cause = named or best.term.cause
    out = t.to_dict()
    if _key(t.term) in declined:
        out["why_not"] = declined[_key(t.term)]
    elif t.significant:
        if t.term.label in rivals:
            out["why_not"] = f"the data cannot tell it from {cause} (the same validation fit, to within the noise)"
        elif t.dof > best.dof and t.test.sse_after < best.test.sse_after and set(t.channels) == set(best.channels):
            out["why_not"] = f"{cause} has fewer parameters and fits as well (within 5 % or one paired SE)"
        elif shared := ", ".join(sorted(set(t.channels) & set(best.channels))):
            out["why_not"] = f"{cause} explains more of the validation error of {shared}"
        else:
            out["why_not"] = f"tested again in the next round, after {cause} on {best.term.channel}"
    return out


def _without_columns(best, group, tested) -> tuple:
    """(best, group, tested) with every candidate's columns dropped (members' too), the same
    Tested appearing as one object wherever it did: a round's columns are views of one block, and
    a kept one keeps all of it through the refits that follow."""
    bare: dict = {}

    def strip(t):
        if id(t) not in bare:
            members = tuple(strip(m) for m in t.candidate.members)
            bare[id(t)] = replace(t, candidate=replace(t.candidate, columns={}, refit=None, members=members))
        return bare[id(t)]

    return (None if best is None else strip(best)), [strip(g) for g in group], [strip(t) for t in tested]
