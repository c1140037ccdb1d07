"""The pneumatic section's plots (thesis ch. 4 figures); its pages and words are in
:mod:`diegocal.report.pneumatic`.

Fig. 4.13 (drift of open-loop prediction against horizon), the distribution of the 2-s drift,
Fig. 4.10 (steady-state curves), Fig. 4.11 (next-step Δp) and Fig. 4.12 (pressure integrated
from grid points). Pressures are in the pressure stream's unit, kPa for the bundled robots.
"""

from __future__ import annotations

import numpy as np

from diegocal.pneumatic.data import ChamberData
from diegocal.pneumatic.files import PneumaticModel
from diegocal.pneumatic.model import steady_state
from diegocal.pneumatic.predict import HORIZON_S, Drift, next_step, predict_with_resets, reset_starts
from diegocal.report.style import COLORS, axes_or_new, legend_above_data, trace_style

U_GRID = np.linspace(3.0, 7.0, 161)  # §4.5: commands 3-7 V
UNIT = "kPa"  # the pressure stream's unit in the bundled robots ("pu" in diegocal.pneumatic)
#: The thesis's drift levels (§4.5.4): "less than 10 % of Pc - Pr, and usually less than 4 %".
LEVELS = ((4.0, "4 %: the thesis's usual drift", ":"), (10.0, "10 %: the thesis's bound", "--"))
#: Chambers a plot tells apart by colour and legend; more are drawn alike, without a legend.
MAX_NAMED = 10


def _levels(ax, vertical: bool = False) -> None:
    for x, label, ls in LEVELS:
        (ax.axvline if vertical else ax.axhline)(x, ls=ls, color=COLORS["residual"], lw=0.9, label=label)


def stored_drift(model: PneumaticModel) -> dict[str, Drift]:
    """The drift curves pneumatic.yaml stores (``drift_curve``, a point every ``curve_step_s``) as
    :class:`Drift` records in fractions of Pc − Pr (span 1)."""
    meta = model.meta.get("drift") or {}
    step = float(meta.get("curve_step_s", 0.1))
    out = {}
    for name, c in model.chambers.items():
        curve = np.asarray(c.raw.get("drift_curve") or [], float)
        if curve.size:
            out[name] = Drift(np.arange(curve.size) * step, curve, 1.0, int(meta.get("starts", 0) or 0))
    return out


def _pooled(drifts: dict[str, Drift], at: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(horizon, RMS over chambers of rms / span), on ``at`` (s) when given, else on the shortest
    common horizon."""
    n = min(d.rms.size for d in drifts.values())
    t = next(iter(drifts.values())).horizon[:n] if at is None else at
    curves = [np.interp(t, d.horizon, d.rms / d.span) for d in drifts.values()]
    return t, np.sqrt(np.mean(np.square(curves), axis=0))


def step_words(drifts: dict[str, Drift]) -> str:
    """The step between the points of a drift curve, in words ("a point every 10 ms")."""
    h = next(iter(drifts.values())).horizon
    step = float(np.median(np.diff(h))) if h.size > 1 else 0.0
    return f"a point every {1000 * step:.0f} ms" if round(step, 6) < 0.1 else f"a point every {step:.2g} s"


def plot_drift_curves(fit: dict[str, Drift], ax=None, heldout: dict[str, Drift] | None = None):
    """Fig. 4.13: RMS prediction error vs horizon per chamber on the fit log (thin), pooled over
    chambers (thick), in % of (Pc − Pr); ``heldout``: the pooled curve on a held-out log, drawn at
    the fit log's horizons (the same points in time)."""
    ax = axes_or_new(ax)
    for k, d in enumerate(fit.values()):
        label = "one chamber (fit log)" if k == 0 else None
        ax.plot(d.horizon, 100 * d.rms / d.span, lw=0.5, color=COLORS["model"], alpha=0.4, label=label)
    t, pooled = _pooled(fit)
    ax.plot(t, 100 * pooled, lw=2, color="k", label="all chambers pooled (fit log)")
    if heldout:
        t, pooled = _pooled(heldout, at=t[t <= min(d.horizon[-1] for d in heldout.values())])
        ax.plot(t, 100 * pooled, lw=2, color=COLORS["baseline"], label="all chambers pooled (held-out log)")
    _levels(ax)
    starts = next(iter(fit.values())).n_starts or "?"
    ax.set_xlabel(f"time since the last measured pressure [s]  ({starts} starts per chamber; {step_words(fit)})")
    ax.set_ylabel("RMS error [% of Pc − Pr]")
    ax.set_title(f"Drift of open-loop pressure prediction, {len(fit)} chambers (Fig. 4.13)")
    ax.legend(fontsize=6, loc="upper left")
    return ax


def plot_drift_histogram(model: PneumaticModel, ax=None, heldout=None):
    """Distribution of the 2-s drift over chambers, % of (Pc - Pr); held-out drifts beside."""
    ax = axes_or_new(ax)
    d = np.array([c.raw.get("drift_2s", np.nan) for c in model.chambers.values()], float) * 100
    d = d[np.isfinite(d)]
    top = max([12.0, *d] + ([100 * x.final for x in heldout.values()] if heldout else []))
    bins = np.linspace(0, top, 25)
    ax.hist(d, bins=bins, color=COLORS["model"], alpha=0.8, label=f"fit log ({d.size} chambers)")
    if heldout:
        h = np.array([x.final for x in heldout.values()]) * 100
        ax.hist(h, bins=bins, histtype="step", lw=1.5, color=COLORS["baseline"], label=f"held-out log ({h.size})")
    _levels(ax, vertical=True)
    ax.set_xlabel("RMS error 2 s after the last measured pressure [% of Pc − Pr]")
    ax.set_ylabel("chambers")
    ax.set_title(f"2-s drift on the fit log: median {np.median(d):.1f} %, worst {d.max():.1f} %")
    ax.legend(fontsize=6)
    return ax


def plot_steady_state(model: PneumaticModel, sweep=None, names=None, ax=None):
    """Fig. 4.10: fitted s(u) at rest (vdot = 0, mid travel) and, if given, the measured sweep.

    sweep : dict name -> (u (T,), p (T,)) from a locked-cylinder log, or None
    """
    ax = axes_or_new(ax)
    names = list(names or model.chambers)
    named = len(names) <= MAX_NAMED
    for i, name in enumerate(names):
        c = model.chambers[name].params
        style = trace_style(i) if named else {"color": COLORS["model"]}
        if sweep and name in sweep:
            u, p = sweep[name]
            ax.plot(u, p, ".", ms=1, color=style["color"], alpha=0.3)
        s = steady_state(c, U_GRID, c.v_ref, 0.0)
        ax.plot(U_GRID, s, lw=1 if named else 0.4, label=name if named else None, **style)
    ax.set_xlabel(f"valve command u [V]  ({U_GRID.size} points, 3-7 V as in §4.5)")
    ax.set_ylabel(f"steady-state pressure s(u) [{UNIT}]")
    src = "fitted s(u) (lines) and measured sweep (dots)" if sweep else "fitted s(u)"
    ax.set_title(f"{len(names)} chamber(s): {src} (Fig. 4.10)")
    if named:
        ax.legend(fontsize=6)
    return ax


def plot_delta_p(data: ChamberData, params, ax=None, window=(0.0, 10.0)):
    """Fig. 4.11: measured p_{t+h} - p_t (light) and the model's one-step change (dark)."""
    ax = axes_or_new(ax)
    sel = np.flatnonzero((data.time[:-1] >= window[0]) & (data.time[:-1] < window[1]) & data.steps)
    pred = next_step(params, data)[sel]
    ax.plot(data.time[sel], data.p[sel + 1] - data.p[sel], color="0.7", lw=1.5, label="measured")
    ax.plot(data.time[sel], pred - data.p[sel], color=COLORS["model"], lw=0.7, label="model, from the measured p_t")
    h_ms = 1000 * float(np.median(np.diff(data.time)))
    ax.set_xlabel(f"time [s]  ({sel.size} steps)")
    ax.set_ylabel(f"Δp per {h_ms:.0f} ms step [{UNIT}]")
    ax.set_title(f"{data.name}: pressure change, measured vs model (Fig. 4.11)")
    legend_above_data(ax)
    return ax


def reset_times(data: ChamberData, horizon_s: float = HORIZON_S) -> np.ndarray:
    """(R,) s: where :func:`~diegocal.pneumatic.predict.predict_with_resets` re-initialises the
    prediction with the measured pressure (:func:`~diegocal.pneumatic.predict.reset_starts`)."""
    return data.time[reset_starts(data, horizon_s)]


def plot_integrated(data: ChamberData, params, predicted=None, ax=None, window=(0.0, 10.0)):
    """Fig. 4.12: measured pressure (light) and the model integrated open loop (dark), re-initialised
    with the measured pressure at the dotted lines."""
    ax = axes_or_new(ax)
    pred = predict_with_resets(params, data) if predicted is None else predicted
    sel = (data.time >= window[0]) & (data.time < window[1])
    ax.plot(data.time[sel], data.p[sel], color="0.7", lw=1.5, label="measured")
    ax.plot(data.time[sel], pred[sel], color=COLORS["model"], lw=0.7, label="model integrated open loop")
    resets = reset_times(data)
    for k, t in enumerate(resets[(resets >= window[0]) & (resets < window[1])]):
        label = "re-initialised with the measured pressure" if k == 0 else None
        ax.axvline(t, ls=":", color="0.3", lw=0.8, label=label)
    ax.set_xlabel(f"time [s]  ({int(sel.sum())} samples)")
    ax.set_ylabel(f"pressure [{UNIT}]")
    ax.set_title(f"{data.name}: open-loop pressure from the dotted grid lines (Fig. 4.12)")
    legend_above_data(ax)
    return ax
