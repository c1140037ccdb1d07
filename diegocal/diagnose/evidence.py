"""The evidence of a finding: the variable that localises it and the residual's binned mean against
that variable before and after it (issue #13, report section: "the evidence plot (residual against
the variable that localises it, before and after, with its band)").

Called by :func:`~diegocal.diagnose.engine.run_unit`.
"""

from __future__ import annotations

import numpy as np

from diegocal.causes import CAUSES
from diegocal.diagnose.show import signed_edges
from diegocal.diagnose.stats import binned_means, quantile_edges
from diegocal.diagnose.types import Residuals
from diegocal.evaluate import sub_blocks
from diegocal.terms import Term


def evidence_variable(term: Term, res: Residuals, shown: str | None = None) -> str | None:
    """The variable that localises a term: its region's, else its channel's first variable (or
    that of ``shown``, the channel its evidence is drawn for)."""
    if term.region is not None and term.region.variable in res.variables:
        return term.region.variable
    against = getattr(CAUSES.get(term.cause), "shown_against", None)
    if against and f"{against}.{term.channel}" in res.variables:  # friction's shape: against the velocity
        return f"{against}.{term.channel}"
    for c in [term.channel, *([shown] if shown else []), *res.channels]:
        names = res.channel_variables.get(c)
        if names:
            return names[0]
    return None


def direction(term: Term) -> tuple[str | None, tuple[str, float] | None]:
    """(signed_by, partner) of a term's evidence curve (:func:`curves`): the registry's
    ``signed_by`` (friction: the residual times sign(qd)), and for a cause with a partner channel and
    a ratio (a motor that drives two joints) that channel and the ratio; (None, None) otherwise."""
    entry = CAUSES.get(term.cause)
    if entry is None or entry.signed_by is None:
        return None, None
    key = entry.partner
    partner = (term.extra[key], float(term.extra["ratio"])) if key in term.extra and "ratio" in term.extra else None
    return entry.signed_by, partner


def curves(
    res, res_new, channel, variable, shown, length, train, n_bins, exclude, signed_by=None, partner=None
) -> dict:
    """Residual mean per bin of ``variable`` on the shown (validation + held-out) samples, before
    and (when ``res_new`` is given) after, with block standard errors: the evidence plot's data.
    ``signed_by`` (a cause's :attr:`~diegocal.causes.Cause.signed_by`, e.g. "qd"): the residual is
    multiplied by the sign of that variable on ``channel`` (``signed_by`` in the output names it),
    unless that is the variable binned; ``partner`` (channel, ratio): of that variable plus ratio
    times the partner's (a motor that drives two joints)."""

    x = np.asarray(res.variables[variable], float)
    sign_name, motion = None, None
    if signed_by and variable.split(".", 1)[0] != signed_by:  # binned by a velocity: the sign shows
        own = res.variables.get(f"{signed_by}.{channel}")
        other = res.variables.get(f"{signed_by}.{partner[0]}") if partner else None
        if own is not None and (partner is None or other is not None):
            sign_name = f"{signed_by}.{channel}"
            motion = np.asarray(own, float)
            if partner:
                k = abs(partner[1])
                times = "" if k == 1 else f"{k:g}·"
                sign_name += f" {'+' if partner[1] >= 0 else '−'} {times}{signed_by}.{partner[0]}"
                motion = motion + partner[1] * np.asarray(other, float)
    sign = 1.0
    if motion is not None:  # at rest the direction is unknown: those samples are left out
        sign = np.sign(motion)
        sign[sign == 0] = np.nan
    # a velocity: bins that never straddle zero, fine near it (friction's shape there)
    edges = signed_edges(x[train], n_bins) if variable.startswith("qd.") else quantile_edges(x[train], n_bins)
    cl = sub_blocks(shown, length)
    out = {}
    for name, r in (("before", res), ("after", res_new)):
        if r is None or channel not in r.channels:
            continue
        v = np.array(r.channels[channel], float)
        if exclude and channel in exclude:
            v[np.asarray(exclude[channel], bool)] = np.nan
        scalar = (v if v.ndim == 1 else np.linalg.norm(v, axis=1)) * sign
        out[name] = binned_means(np.where(shown, scalar, np.nan), x, cl, edges, variable).to_dict()
    out["unit"] = res.units.get(channel, "")
    out["channel"] = channel
    seen = x[shown & np.isfinite(x)]
    if seen.size:  # the variable's extent on the samples shown (the bins' medians lie inside it)
        out["reach"] = [float(seen.min()), float(seen.max())]
    if sign_name:
        out["signed_by"] = sign_name
    return out
