"""What a diagnosis could not have seen: the smallest effect of each tested cause it would find.

"Nothing significant" is only as strong as the test's power on that channel: a pot's curve on a
joint that the pot alone fixes is taken up by the tracked angle, and a friction on a joint that
barely moves leaves no trace. A tested candidate's validation test regresses the residual on the
correction a fitted on the training rows (:func:`~.stats.out_of_sample_test`): an effect k·a is
found, t = k / se above the candidate's threshold, about 80 % of the time when
k ≥ (threshold + Z_POWER)·se; and it must remove ``min_gain`` of the validation (and held-out)
mean squared error it is judged on, which an effect of RMS e on n rows does when
n e² ≥ min_gain / (1 − min_gain) Σ r² (over its own channel's rows, or all its channels'). The
larger of the two RMS, on the channel the candidate acts on most (its own where it has one), is
the candidate's *detection limit*. It is taken in the last round, on the residual of the model
with every finding (an effect beside those found), and is conditional on the correction's shape,
which for a cause absent from the data is the training noise's: a guide to what the data could
have shown, not a bound.
"""

from __future__ import annotations

import numpy as np

#: One-sided normal quantile of 80 % power.
Z_POWER = 0.8416


def detectable(se: float, threshold: float, r: np.ndarray, a: np.ndarray, error: float, weight: float,
               min_gain: float):
    """(RMS in the channel's unit, the same over that channel's residual RMS, the bar that sets it:
    "power" or "min_gain") of the smallest effect shaped like ``a`` that a test of standard error
    ``se`` and critical t ``threshold`` finds with 80 % power and that removes ``min_gain`` of
    ``error`` (Σ r² over the rows the candidate's gain is taken on); ``r``, ``a``: one channel's
    weighted residual and correction on its validation rows (``weight``: the channel's weight).
    inf without a test."""
    r, a = np.asarray(r, float), np.asarray(a, float)
    sigma = float(np.sqrt(np.mean(r * r))) if r.size else 0.0
    if not np.isfinite(se) or a.size == 0 or not error > 0 or sigma == 0:
        return float("inf"), float("inf"), "power"
    tested = (threshold + Z_POWER) * se * float(np.sqrt(np.mean(a * a)))
    paid = float(np.sqrt(min_gain / (1.0 - min_gain) * error / a.size))
    multiple, by = (tested, "power") if tested > paid else (paid, "min_gain")
    return multiple / weight, multiple / sigma, by


def detection_limits(tested, units: dict, in_span=()) -> list[dict]:
    """{cause, channel, seen_on, rms, unit, of_residual, by} per tested candidate that names one channel
    (a common cause's is its members'), least detectable first (largest ``of_residual``: over the
    channel's residual RMS, the model's with every finding); a (cause, channel) of ``in_span``, a
    candidate the adapter did not offer because the model's own parameters take it up whole (an
    armature in an identified rigid body), has an infinite limit, set by "span"."""
    out = [{"cause": c, "channel": ch, "seen_on": ch, "rms": float("inf"), "unit": units.get(ch, ""),
            "of_residual": float("inf"), "by": "span"} for c, ch in dict.fromkeys(in_span)]
    for t in tested:
        if t.detectable is None or t.candidate.members:
            continue
        on, rms, multiple, by = t.detectable
        if np.isfinite(rms):
            out.append({"cause": t.term.cause, "channel": t.term.channel, "seen_on": on, "rms": rms,
                        "unit": units.get(on, ""), "of_residual": multiple, "by": by})
    return sorted(out, key=lambda d: -d["of_residual"])


def unseen(limits, findings) -> tuple[dict, ...]:
    """The limits of the (cause, channel) pairs no finding names."""
    named = {(f.cause, f.channel) for f in findings}
    return tuple(d for d in limits if (d["cause"], d["channel"]) not in named)


def limits_words(limits, shown: int = 3) -> str:
    """The detection limits in a sentence (the command's summary, the report): how many the gain a
    finding needs sets and how many the data's power, their span, the ``shown`` least detectable
    (none where all tie at the lowest), and the causes the model's own parameters take up whole."""
    limits = list(limits)
    unseeable = [d for d in limits if d.get("by") == "span"]
    limits = [d for d in limits if d.get("by") != "span"]
    out = []
    if limits:
        power = sum(d.get("by") == "power" for d in limits)
        low, high = (f"{min(d['of_residual'] for d in limits):.2g}", f"{max(d['of_residual'] for d in limits):.2g}")
        above = [d for d in limits if f"{d['of_residual']:.2g}" != low][:shown]  # ties at the lowest say nothing
        least = ", ".join(f"{d['cause']} on {d['channel']} ({d['rms']:.2g} {d['unit']} RMS on {d['seen_on']}, "
                          f"{d['of_residual']:.2g}× the residual there)" for d in above)
        out.append(f"{len(limits)} tested cause-channel pairs, {len(limits) - power} limited by the gain a finding "
                   f"needs and {power} by the data's power, are found once their effect is "
                   f"{low if low == high else f'{low}-{high}'}× the residual RMS on its channel"
                   + (f"; least detectable: {least}" if least else ""))
    if unseeable:
        out.append("not testable, the model's own parameters taking them up whole: "
                   + ", ".join(f"{d['cause']} on {d['channel']}" for d in unseeable))
    return "; ".join(out)
