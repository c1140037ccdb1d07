"""diagnosis.yaml: the contract of DESIGN.md ("Diagnosis output"), extended.

::

    kind: diagnosis            # + the bundle header (robot, log, command, version, created)
    domain: dynamics
    baseline: {model: rigid_body+viscous+coulomb, heldout_rmse: {joint1: 0.41, ...}, unit: N·m}
    findings:                  # most important first; [] when nothing is significant
      - cause: position_friction
        channel: joint3
        region: {variable: q.joint3, low: 1.9, high: 2.3}
        parameters: {coulomb: {value: 0.31, stderr: 0.01, unit: N·m}, ...}
        gain: {rmse_before: 0.41, rmse_after: 0.12, reduction: 0.71}     # held-out blocks
        kind: term             # term | fault | unexplained
        unit: N·m
        evidence: {validation_gain, t, threshold_t, variable, curves: {before, after, unit, channel, reach, signed_by?}}
                               # + heldout_leaves_out: [t0, t1], s (a time region's edge between training blocks)
                               # + indistinguishable_from: [channel, ...] (the same cause there fits the same)
                               # + indistinguishable_causes: [cause:channel, ...] (another cause fits the same)
                               # + restated: why in words (a payload no body can be, named link_inertia)
                               # + stand_in: {term, validation_gain} (unexplained: the term that stood in),
                               #   with what beat it: declined: {term, why} or rival: {model, tau_s,
                               #   open_loop_validation_gain, term_open_loop_validation_gain}
        runners_up: [{cause, channel, region, validation_gain, t, threshold_t, significant}, ...]
    minor_faults:              # flagged by a fault detector; writing them off removed under min_gain
      - {cause: marker_outliers, channel: m2, readings: 14, gain: {...}, written_off: true}
    extended_model: run.extended.sgp
    extended: {model: ..., heldout_rmse: {...}}
    blocks: {train: [[t0, t1], ...], validation: [...], heldout: [...]}   # seconds
    options: {alpha: 0.01, min_gain: 0.05, max_rounds: 6, n_blocks: 10}
    residual_tests: {channel: {correlation_time_s, change_point: {p, time}, variables: {...}}}
                               # + change_point_signed (a joint: the residual times sign(qd), friction's share)
    declined: [{cause, channel, why}]  # significant on validation, not added (why in words)
    detection_limits:          # per tested cause and channel no finding names, least detectable first:
      - {cause, channel, seen_on, rms, unit, of_residual, by}   # the smallest effect found 80 % of the time:
                               # its RMS on channel ``seen_on``, the same over that channel's residual RMS,
                               # and the bar that sets it (power: the test's; min_gain: the gain a finding needs;
                               # span: not testable, the model's own parameters take it up whole; rms .inf)
    converged: true            # false: a kept fit stopped at a cap before its tolerance
    unconverged: []            # which, in words (STAC's iterations, a term's refinement, a chamber's budget)

Pneumatics has one unit per chamber: ``baseline`` and ``extended`` hold every chamber's held-out
RMSE, and each finding names its chamber as its channel.
"""

from __future__ import annotations

import numpy as np

from diegocal.io.bundle import LAYOUT
from diegocal.io.files import to_plain
from diegocal.terms import Term


def _clean(v):
    return to_plain(v, nan_as_none=True)


def _rmse_map(scores) -> dict:
    out = {}
    for s in scores:
        for c, r in zip(s.channels, s.rmse, strict=True):
            out[c] = None if not np.isfinite(r) else float(r)
    return out


def _units(scores) -> str:
    units = sorted({s.unit for s in scores if s.unit})
    return ", ".join(units)


def finding_dict(f, units: dict) -> dict:
    term: Term = f.term
    d = term.to_dict()
    out = {
        "cause": d["cause"],
        "channel": d["channel"],
        "region": d["region"],
        "parameters": d["parameters"],
        "gain": _clean(f.gain()) or None,
        "kind": f.kind,
        "unit": _finding_unit(f, units),
        "evidence": _clean(
            {k: v for k, v in f.evidence.items() if k != "channels"} | {"channels": f.evidence.get("channels", [])}
        ),
    }
    if d.get("extra"):
        out["extra"] = d["extra"]
    out["runners_up"] = _clean(list(f.runners_up))  # [] when no other candidate was tested
    return out


def _finding_unit(f, units: dict) -> str:
    """The unit of a finding's gain: its channel's where it is scored on it, else the unit of the
    first channel it acts on (a joint's offset seen by markers: m)."""
    acts_on = f.evidence.get("gain_channels") or f.evidence.get("channels") or [f.term.channel]
    if f.term.channel in units and f.term.channel in acts_on:
        return units[f.term.channel]
    return units.get(acts_on[0], "")


def diagnosis_dict(diag, extended_model: str | None = None) -> dict:
    """The diagnosis.yaml mapping of a :class:`~diegocal.diagnose.Diagnosis` (without the header)."""
    units = diag.units
    channel_units = {}
    for u in units:
        channel_units.update({c: u.units.get(c, u.baseline_score.unit) for c in u.baseline_score.channels})
    base = [u.baseline_score for u in units]
    ext = [u.extended_score for u in units]
    o = diag.options
    return {
        "layout": LAYOUT,
        "domain": diag.domain,
        "baseline": {
            "model": units[0].baseline_model if len(units) == 1 else _common_model(u.baseline_model for u in units),
            "heldout_rmse": _rmse_map(base),
            "unit": _units(base),
            "units": channel_units,
        },
        "findings": [finding_dict(f, channel_units) for f in diag.findings],
        "minor_faults": [_minor_fault(f) for u in units for f in u.minor_faults],
        "extended_model": extended_model,
        "extended": {
            "model": units[0].extended_model if len(units) == 1 else "per chamber (see findings)",
            "heldout_rmse": _rmse_map(ext),
            "unit": _units(ext),
        },
        "blocks": diag.blocks.to_dict(diag.time),
        "options": {"alpha": o.alpha, "min_gain": o.min_gain, "max_rounds": o.max_rounds, "n_blocks": o.n_blocks},
        "residual_tests": _clean({(f"{u.unit}/{c}" if u.unit else c): v for u in units for c, v in u.show.items()}),
        "declined": [dict(d) for u in units for d in u.declined],
        "detection_limits": [_limit(d) for u in units for d in u.detection_limits],
        "converged": not any(u.unconverged for u in units),
        "unconverged": [f"{u.unit}: {why}" if u.unit else why for u in units for why in u.unconverged],
    }


def _limit(d: dict) -> dict:
    """A detection limit (:mod:`.limits`) at four significant digits."""
    return {**d, "rms": float(f"{d['rms']:.4g}"), "of_residual": float(f"{d['of_residual']:.4g}")}


def _minor_fault(f) -> dict:
    """A data fault that is no finding: what the detector flagged, what writing it off changed on
    the held-out blocks, and whether the extended model writes it off all the same."""
    return {
        "cause": f.cause,
        "channel": f.channel,
        "readings": f.evidence.get("readings", f.evidence.get("frames")),  # flagged (a swap: frames)
        "gain": {k: float(v) for k, v in f.gain().items()},
        "written_off": bool(f.evidence.get("written_off")),
    }


def _common_model(models) -> str:
    models = list(dict.fromkeys(models))
    return models[0] if len(models) == 1 else "; ".join(models)


def pooled_heldout_rmse(diagnosis: dict) -> dict[str, tuple[float, float]]:
    """Unit -> (baseline, extended) held-out RMSE of a diagnosis (its diagnosis.yaml mapping), pooled
    as the root mean square over the channels measured in that unit, never across units (NaN where
    no channel has one)."""
    base, ext = diagnosis.get("baseline") or {}, diagnosis.get("extended") or {}
    units = base.get("units") or {}

    def pooled(block: dict, unit: str) -> float:
        x = [v for c, v in (block.get("heldout_rmse") or {}).items() if v is not None and units.get(c, unit) == unit]
        return float(np.sqrt(np.mean(np.square(x)))) if x else float("nan")

    return {u: (pooled(base, u), pooled(ext, u)) for u in dict.fromkeys(units.values() or [base.get("unit", "")])}


def shifting_channels(diagnosis: dict) -> list[tuple[str, float, float | None]]:
    """(channel, p, time s) of the channels whose baseline residual's mean shifts over the session
    (the CUSUM tests of ``residual_tests``, p under the diagnosis's ``alpha`` shared by the tests),
    in a diagnosis without findings: structure in time that no term names (a drift, or an effect
    that part of the session's motion excites), most significant first. A finding changes what the
    others' residuals hold (a pot's curve moves the tendons' fit), so with one the baseline's tests
    say nothing of what is left."""
    if diagnosis.get("findings"):
        return []
    tests = diagnosis.get("residual_tests") or {}
    alpha = float((diagnosis.get("options") or {}).get("alpha", 0.01))
    kinds = ("change_point", "change_point_signed")  # the mean; the residual times sign(qd) (friction)
    n = sum(k in (entry or {}) for entry in tests.values() for k in kinds) or 1
    out = []
    for key, entry in tests.items():
        found = [c for k in kinds if (c := (entry or {}).get(k)) and c.get("p") is not None]
        if found and (least := min(found, key=lambda c: c["p"]))["p"] < alpha / n:
            out.append((key, float(least["p"]), least.get("time")))
    return sorted(out, key=lambda x: x[1])


def weak_structure(diagnosis: dict) -> list[tuple[str, str, float]]:
    """(channel, variable, validation gain) of the baseline residual's binned tests that are
    significant, in a diagnosis without findings: structure too small to pay for a finding (under
    ``unexplained_min_gain`` of the validation error), said so that "nothing significant" is not."""
    if diagnosis.get("findings"):
        return []
    tests = diagnosis.get("residual_tests") or {}
    return [
        (key, var, float(v.get("validation_gain") or 0.0))
        for key, entry in tests.items()
        for var, v in ((entry or {}).get("variables") or {}).items()
        if (v or {}).get("significant")
    ]

