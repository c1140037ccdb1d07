"""Stand-ins: a term that the engine would name while something else explains its channel's
structure better (:func:`~diegocal.diagnose.engine.run_unit`'s choice of a round's best). Its
channel is then ``unexplained``, with the term named as the stand-in: a flexible model of the
channel's own state explains far more, or most of what the term leaves (:func:`outshone`), a
flexible model of a neighbouring sensor explains more (:func:`spilled`), a named term of the
channel explained more on the validation rows but was declined, its extension not confirmed on
the held-out rows (:func:`declined_rival`), or a model of another shape that no cause names
explains more of what the adapter scores (a chamber's pressure read through a filter:
:mod:`~diegocal.diagnose.pneumatics_filter`). A term judged on several channels can also lose to
a rival of its own channel judged on that channel alone, when both are refitted into the model
(:func:`refit_rival`): the rival is then named.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from diegocal.causes import search_end
from diegocal.diagnose.evidence import curves
from diegocal.diagnose.selection import evaluate_candidates
from diegocal.diagnose.show import binned_candidate, flexible_candidate, flexible_variables, unexplained_region
from diegocal.diagnose.types import EngineOptions, Finding, Tested, column_rows
from diegocal.terms import Term

#: A named term must explain at least this share of what the most flexible model of its channel's
#: own state explains on the validation rows (:func:`~diegocal.diagnose.show.flexible_candidate`);
#: less, and it is a stand-in for structure of another shape: the channel is ``unexplained``.
STAND_IN_SHARE = 0.5


def own_channel(t: Tested) -> str:
    """The channel a tested term is judged on: its own when it acts there, else the one it acts on
    most (a payload: the joint its weight loads most), else its first."""
    if t.term.channel in t.channels:
        return t.term.channel
    return t.strongest[0] if t.strongest else t.channels[0]


#: ... or it must leave its channel's flexible model less than this share of what remains (a
#: channel with context, :func:`leaves_most`).
LEFT_SHARE = 0.5


def outshone(best: Tested, res, weights, train, val, options: EngineOptions, exclude, tested=()) -> Tested | None:
    """The flexible model's test on ``best``'s channel when it is significant and ``best`` explains
    less than STAND_IN_SHARE of what it explains, or leaves most of it (:func:`leaves_most`;
    ``tested``: the round's candidates); None otherwise: the term may be named."""
    own = own_channel(best)
    cand = flexible_candidate(res, own, train, options.n_bins)
    if cand is None:
        return None
    (flex,) = evaluate_candidates([cand], res, weights, train, val, options, exclude) or (None,)
    if flex is None or flex.test.t <= flex.threshold or flex.test.gain < options.unexplained_min_gain:
        return None  # no structure worth an ``unexplained`` finding beside the term
    if best.strongest:  # judged on the channel it acts on most (_own): its gain there
        gain = best.strongest[1]
    else:  # over all its channels, or on its own (the flexible model's) where that is larger
        gain = max(best.test.gain, best.own_gain if best.own_gain is not None else -np.inf)
    if gain < STAND_IN_SHARE * flex.test.gain:
        return flex
    return flex if leaves_most(best, tested, res, weights, train, val, options, exclude) else None


def leaves_most(best: Tested, tested, res, weights, train, val, options: EngineOptions, exclude) -> bool:
    """Whether ``best``, fitted on its channel, leaves to the channel's flexible model (with the
    context: the other joints' angles) at least LEFT_SHARE of the validation error that remains,
    and no other significant term of the round on that channel, fitted with it, takes that up: the
    term then fits part of a structure of another shape through what its column shares with it.
    A user trial's hose on a Kinova's joint 2 (a torque linear in q3) was named a gain there: the
    gain's column, joint 2's torque, hangs on q3; it removed 76 % of the joint's validation error,
    the flexible model 92 %, and of what the gain left the flexible model removed 69 %. A true
    gain leaves it 4-26 % (the rest a friction's shape that later rounds name); a load friction
    beside a friction near zero velocity leaves 56 %, which that friction, fitted with it, takes
    up. Channels without context are judged by STAND_IN_SHARE alone."""
    own = own_channel(best)
    if not res.context.get(own) or best.candidate is None or own not in best.candidate.columns:
        return False
    if _left(res, own, [best], weights, train, val, options, exclude) < LEFT_SHARE:
        return False
    others = [
        t for t in tested
        if t is not best and t.significant and t.term.cause != best.term.cause and not t.candidate.members
        and own_channel(t) == own and own in t.candidate.columns
    ]
    return all(_left(res, own, [best, t], weights, train, val, options, exclude) >= LEFT_SHARE for t in others)


def _left(res, own: str, terms, weights, train, val, options: EngineOptions, exclude) -> float:
    """The validation gain of ``own``'s flexible model (0 where it is not significant) on what the
    least-squares fit of ``terms``' columns there, on the training rows, leaves of its residual."""
    r = np.array(res.channels[own], float)
    if own in exclude:
        r[np.asarray(exclude[own], bool)] = np.nan
    C = np.hstack([np.asarray(column_rows(t.candidate.columns, own, slice(None)), float).reshape(r.size, -1)
                   for t in terms])
    ok = np.asarray(train, bool) & np.isfinite(r) & np.isfinite(C).all(axis=1)
    if ok.sum() <= C.shape[1]:
        return 0.0
    coef = np.linalg.lstsq(C[ok], r[ok], rcond=None)[0]
    left = replace(res, channels={**res.channels, own: r - C @ coef})
    cand = flexible_candidate(left, own, train, options.n_bins)
    got = evaluate_candidates([cand], left, weights, train, val, options, exclude) if cand is not None else ()
    return next((t.test.gain for t in got if t.test.t > t.threshold), 0.0)


#: A channel of a common cause (one cause tested on several channels at once) is added only with
#: at least this t of its own (about a 5 % two-sided level for one test).
MEMBER_T = 2.0


def same_cause_beside(best: Tested, tested, declined, res, weights, train, val, options, exclude,
                      stood: dict | None = None, neighbours=None) -> list[Tested]:
    """The other significant candidates of ``best``'s cause on channels ``best`` does not act on
    (friction's shape on every joint at once): one cause, added in the same round rather than a
    round per channel; each passes the stand-in tests of its own channel (:func:`stands_in`); one
    that fails goes to ``stood``: its channel is left to later rounds, and ``unexplained`` at the
    end unless a later finding takes it up (the engine's ``pending``)."""
    out, used = [], set(best.channels)
    for t in tested:
        if t is best or not t.significant or t.term.cause != best.term.cause or set(t.channels) & used:
            continue
        if stands_in(t, tested, declined, res, weights, train, val, options, exclude, stood, neighbours):
            continue
        out.append(t)
        used |= set(t.channels)
    return out


def members_kept(best: Tested, tested, declined, res, weights, train, val, options, exclude,
                 stood: dict | None = None, neighbours=None) -> list[Tested]:
    """The channels' terms of a common cause (``best.candidate.members``) that have evidence of
    their own (t at least MEMBER_T on their channel's validation rows and ``min_gain``: the common
    test holds the family-wise rate, not each channel's; not declined in an earlier round) and pass
    the stand-in tests of their own channel (:func:`stands_in`; one that fails goes to ``stood``).
    A user trial's hose on a Kinova's joint 2 left a Stribeck member there that its flexible model
    beat 0.67 to 0.11, and nothing was said of the joint."""
    out = []
    for t in best.candidate.members:
        if (t.term.cause, t.term.channel) in declined or t.test.t < MEMBER_T or t.gain < options.min_gain:
            continue  # not its own evidence
        if stands_in(t, tested, declined, res, weights, train, val, options, exclude, stood, neighbours):
            continue
        out.append(t)
    return out


def stands_in(t: Tested, tested, declined, res, weights, train, val, options, exclude, stood=None,
              neighbours=None) -> bool:
    """Whether a channel's term added beside a round's best fails a stand-in test of its channel:
    a declined term there explained more, or its flexible model far more, or (``neighbours``: the
    adapter's neighbours' flexible models, as the round's best faces them, :func:`spilled`) a
    neighbouring sensor's model removes more, that sensor then the one left unexplained (a lagging
    pot was a member of a common backlash). The channel and what beat it go to ``stood`` (channel
    -> (term, rival, evidence), as the engine's stand-ins) when given."""
    evidence, own = None, own_channel(t)
    if (rival := declined_rival(t, tested, declined)) is not None:
        evidence = declined_evidence(rival, declined)
    elif (rival := outshone(t, res, weights, train, val, options, exclude, tested)) is None:
        if neighbours is None:
            return False
        rival = spilled(t, neighbours(t.term, t.channels), res, weights, train, val, options, exclude)
        if rival is None:
            return False
        own = rival.term.channel  # a neighbour's flexible model: that sensor is unexplained
    if stood is not None:
        stood.setdefault(own, (replace(t, candidate=None), replace(rival, candidate=None), evidence))
    return True


def spilled(best: Tested, models, res, weights, train, val, options: EngineOptions, exclude) -> Tested | None:
    """The flexible model of a sensor near ``best`` (``models``: candidates, tested together) that
    is significant and removes more of the weighted validation error than ``best`` does (the
    measure :func:`choose` ranks by, comparable across channels; None: none does). A sensor
    misbehaving in a shape no cause names is then misread by the model as an error of a shared
    state (q), and a named term of a neighbour that reads the same state explains a part of it:
    the structure is that sensor's, and it is ``unexplained``."""
    if best.candidate.members or not models:
        return None
    tested = [t for t in evaluate_candidates(models, res, weights, train, val, options, exclude) if t.significant]
    top = max(tested, key=removed, default=None)
    return top if top is not None and removed(top) > removed(best) else None


def searched_out(term, chosen: Tested, why: str) -> tuple | None:
    """A stand-in entry (the engine's: term, what beat it, evidence) for a term declined because a
    parameter ends at the end of its search (``term``: as fitted; ``why``: the decline in words);
    None for any other. The structure it fits is real (its validation test stands), but the value
    the data want lies beyond what the cause describes (the registry's bound: a backlash's
    half-width of 0.1 rad, over which a play is a broken gear): its channel is ``unexplained``,
    its evidence the term's own test and why it was declined, and no later term stands in for that
    structure there. A user trial's backlash at that bound was declined with nothing said of its
    joint."""
    if not any(search_end(term.cause, p.name, p.value) is not None for p in term.parameters):
        return None
    stood = replace(chosen, candidate=None)
    return stood, stood, {"declined": {"term": term.label, "why": why}}


def declined_evidence(rival: Tested, declined: dict) -> dict:
    """A stand-in's evidence where a declined term (:func:`declined_rival`) explained more."""
    return {"declined": {"term": rival.term.label, "why": declined[(rival.term.cause, rival.term.channel)]}}


def declined_rival(best: Tested, tested, declined: dict) -> Tested | None:
    """The declined term (``declined``: (cause, channel) keys) judged on ``best``'s channel and the
    same validation error that removes more of it than ``best`` (None: none does). Its extension was not
    confirmed on the held-out rows, and ``best``, a weaker fit of the same structure, would name a
    cause the data do not single out (a sensor offset declined, then a supply sag that a constant
    offset partly mimics named in its place)."""
    own = own_channel(best)
    rivals = [
        t
        for t in tested
        if (t.term.cause, t.term.channel) in declined
        and t is not best
        and own_channel(t) == own
        and np.isclose(t.test.sse_before, best.test.sse_before)  # the same validation rows and channels
    ]
    top = max(rivals, key=removed, default=None)
    return top if top is not None and removed(top) > removed(best) else None


#: At most this many rivals of a best term are refitted (:func:`refit_rival`), most removed first.
REFIT_RIVALS = 2


def refit_rival(adapter, terms, masks, weights, exclude, best: Tested, tested) -> tuple[Tested, str] | None:
    """(rival, why in words) when a significant term of another cause on the channel ``best`` names, with
    no more parameters but judged on fewer channels (a joint's torque offset on its joint, a gain on
    every joint), removes more of the weighted validation error of ``best``'s channels once each is
    refitted into the model with ``terms`` (None otherwise). The one-step test credits ``best`` with
    what the refit of the shared parameters gains on its other channels and the rival with its own
    channel's only; the refits judge both on the same rows (a Z1 shoulder's 0.3 N·m offset was
    named a gain of −2 %). ``masks``: train, validation."""
    own = best.term.channel
    if best.candidate.members or len(best.channels) < 2 or own not in best.channels:
        return None  # a payload's columns are its own on every joint it loads: no credit to even out
    rivals = sorted(
        (
            t
            for t in tested
            if t.significant
            and not t.candidate.members  # a cause tested on several channels at once is no term to fit
            and t.term.cause != best.term.cause
            and t.term.channel == own
            and set(t.channels) < set(best.channels)
            and t.n_params <= best.n_params
        ),
        key=removed,
        reverse=True,
    )[:REFIT_RIVALS]
    if not rivals:
        return None
    train, val = masks

    def error(t: Tested) -> float:  # the refitted model's weighted validation error on best's channels
        score = adapter.score(adapter.fit(tuple(terms) + (t.term,), train), val, exclude)
        sse = [weights.get(c, 1.0) ** 2 * score.rmse[i] ** 2 * score.n_samples[i]
               for i, c in enumerate(score.channels) if c in best.channels and score.n_samples[i] > 0]
        return float(np.nansum(sse))

    own_error = error(best)
    top = min(((error(t), t) for t in rivals), key=lambda pair: pair[0])
    if not top[0] < own_error:
        return None
    rival = top[1]
    return rival, (f"refitted into the model, {rival.term.label} leaves less of the validation error of "
                   f"{', '.join(best.channels)} ({top[0] / own_error:.0%} of what {best.term.cause} leaves)")


def removed(t: Tested) -> float:
    """The weighted validation error a tested candidate removes."""
    return t.test.sse_before - t.test.sse_after


def stand_in_finding(
    channel, stood: Tested, flex: Tested, res, weights, masks, length, options, exclude, why: dict | None = None
) -> Finding:
    """``unexplained`` on a channel whose best term was a stand-in: its evidence names the term that
    stood in and both validation gains (``flex``: the flexible model, the declined term that
    explained more, or a model of another shape that did; ``why``: the evidence of the last two,
    ``declined`` {term, why} or ``rival`` {model, ...}); the variable shown is the one whose binned
    test explains most."""
    train, val, shown = masks
    variables = list(flexible_variables(res, channel))
    single = [binned_candidate(res, channel, v, train, options.n_bins) for v in variables]
    tested = evaluate_candidates(single, res, weights, train, val, options, exclude)
    variable = max(tested, key=lambda t: t.test.gain).term.region.variable if tested else variables[0]
    region = next((unexplained_region(t) for t in tested if t.term.region.variable == variable), None)
    evidence = {
        "channels": [channel],
        "validation_gain": float(flex.test.gain),
        "t": float(flex.test.t),
        "threshold_t": float(flex.threshold),
        "variable": variable,
        "stand_in": {"term": stood.term.label, "validation_gain": float(stood.gain)},
        **(why or {}),
        "curves": curves(res, None, channel, variable, shown, length, train, options.n_bins, exclude),
    }
    runner = {**stood.to_dict(), "why_not": stood_in_why(channel, flex, why, stood.term.label)}
    return Finding(Term("unexplained", channel, (), region), "unexplained", None, None, evidence, (runner,))


def stood_in_why(channel, flex: Tested, why: dict | None, stood: str = "") -> str:
    """Why the term that stood in (``stood``, its label) was not named, in words, for its row among
    the runners-up (its scores there are the one-step test's; a rival's open-loop ones are said here)."""
    why = why or {}
    if (declined := why.get("declined")) and declined["term"] == stood:  # declined itself (searched_out)
        return f"declined: {declined['why']}"
    if rival := why.get("rival"):
        term = rival.get("term_open_loop_validation_gain")
        return (f"stood in: {rival['model']} removes {rival['open_loop_validation_gain']:.0%} of the open-loop "
                "validation error" + (f", this term {term:.0%}" if term is not None else ""))
    if declined := why.get("declined"):
        return f"stood in: {declined['term']} explained more ({flex.test.gain:.0%}) and was declined"
    return f"stood in: a flexible function of {channel}'s own state explains {flex.test.gain:.0%}"
