"""Report section for pneumatic.yaml (thesis ch. 4 figures; registers itself on import).

Pages: fitted parameters and drift table; Fig. 4.13 (drift of open-loop prediction against
horizon, all chambers); Fig. 4.10 (steady-state curves: fitted s(u) and, when the fit recorded a
locked-cylinder sweep log, the measured sweep); Fig. 4.11 (next-step Δp overlay) and Fig. 4.12
(pressure integrated from grid points) for a typical chamber, rebuilt from the fit log in ``meta``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from diegocal.errors import DiegocalError
from diegocal.io import load_log, load_yaml
from diegocal.pneumatic.data import ChamberData, extract
from diegocal.pneumatic.files import PneumaticModel, load_model
from diegocal.pneumatic.model import steady_state
from diegocal.pneumatic.params import NAMES
from diegocal.pneumatic.predict import next_step, predict_with_resets
from diegocal.report.registry import Section, is_bundle, register_section
from diegocal.report.style import COLORS, axes_or_new, page, save_page, text_page

U_GRID = np.linspace(3.0, 7.0, 161)  # §4.5: commands 3-7 V


def plot_drift_curves(model: PneumaticModel, ax=None):
    """Fig. 4.13: RMS prediction error vs horizon per chamber, in units of (Pc - Pr)/10."""
    ax = axes_or_new(ax)
    step_s = float(model.meta.get("drift", {}).get("curve_step_s", 0.1))
    curves = [np.asarray(c.raw.get("drift_curve", []), float) for c in model.chambers.values()]
    curves = [c for c in curves if c.size]
    for c in curves:
        ax.plot(np.arange(c.size) * step_s, 10 * c, lw=0.5, color=COLORS["model"], alpha=0.4)
    if curves:
        n = min(c.size for c in curves)
        pooled = np.sqrt(np.mean([c[:n] ** 2 for c in curves], axis=0))
        ax.plot(np.arange(n) * step_s, 10 * pooled, lw=2, color="k", label="all chambers (pooled)")
        ax.legend()
    ax.axhline(1.0, ls="--", color=COLORS["residual"], lw=0.8)
    ax.set_xlabel("time since last measured pressure [s]")
    ax.set_ylabel("RMS error [(Pc - Pr)/10]")
    ax.set_title(f"Drift of open-loop pressure prediction, {len(curves)} chambers (Fig. 4.13)")
    return ax


def plot_drift_histogram(model: PneumaticModel, ax=None):
    """Distribution of the 2-s drift over chambers, % of (Pc - Pr)."""
    ax = axes_or_new(ax)
    d = np.array([c.raw.get("drift_2s", np.nan) for c in model.chambers.values()], float) * 100
    ax.hist(d[np.isfinite(d)], bins=20, color=COLORS["model"])
    for x in (4, 10):
        ax.axvline(x, ls="--", color=COLORS["residual"], lw=0.8)
    ax.set_xlabel("RMS error after 2 s [% of Pc - Pr]")
    ax.set_ylabel("chambers")
    ax.set_title(f"2-s drift: median {np.nanmedian(d):.1f} %, max {np.nanmax(d):.1f} %")
    return ax


def plot_steady_state(model: PneumaticModel, sweep=None, names=None, ax=None):
    """Fig. 4.10: fitted s(u) at rest (vdot = 0, mid travel) and, if given, the measured sweep.

    sweep : dict name -> (u (T,), p (T,)) from a locked-cylinder log, or None
    """
    ax = axes_or_new(ax)
    names = list(names or model.chambers)
    for i, name in enumerate(names):
        c = model.chambers[name].params
        color = f"C{i % 10}" if len(names) <= 10 else COLORS["model"]
        if sweep and name in sweep:
            u, p = sweep[name]
            ax.plot(u, p, ".", ms=1, color=color, alpha=0.3)
        s = steady_state(c, U_GRID, c.v_ref, 0.0)
        ax.plot(
            U_GRID,
            s,
            lw=1 if len(names) <= 10 else 0.4,
            color=color,
            label=name if len(names) <= 10 else None,
        )
    ax.set_xlabel("valve command u [V]")
    ax.set_ylabel("pressure")
    src = "fitted s(u) (lines) and measured sweep (dots)" if sweep else "fitted s(u)"
    ax.set_title(f"Steady-state pressure: {src} (Fig. 4.10)")
    if len(names) <= 10:
        ax.legend(fontsize=6)
    return ax


def plot_delta_p(data: ChamberData, params, ax=None, window=(0.0, 10.0)):
    """Fig. 4.11: measured p_{t+h} - p_t (light) and the model's one-step change (dark)."""
    ax = axes_or_new(ax)
    sel = np.flatnonzero((data.time[:-1] >= window[0]) & (data.time[:-1] < window[1]) & data.steps)
    pred = next_step(params, data)[sel]
    ax.plot(data.time[sel], data.p[sel + 1] - data.p[sel], color="0.7", lw=1.5, label="measured")
    ax.plot(data.time[sel], pred - data.p[sel], color=COLORS["model"], lw=0.7, label="model")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("Δp per step")
    ax.set_title(f"{data.name}: pressure change, measured vs model (Fig. 4.11)")
    ax.legend()
    return ax


def plot_integrated(data: ChamberData, params, predicted=None, ax=None, window=(0.0, 10.0)):
    """Fig. 4.12: measured pressure (light) and the model integrated from the grid points (dark)."""
    ax = axes_or_new(ax)
    pred = predict_with_resets(params, data) if predicted is None else predicted
    sel = (data.time >= window[0]) & (data.time < window[1])
    ax.plot(data.time[sel], data.p[sel], color="0.7", lw=1.5, label="measured")
    ax.plot(data.time[sel], pred[sel], color=COLORS["model"], lw=0.7, label="integrated model")
    for t in data.time[sel][::200]:
        ax.axvline(t, ls=":", color="0.5", lw=0.6)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("pressure")
    ax.set_title(f"{data.name}: open-loop pressure from the dotted grid lines (Fig. 4.12)")
    ax.legend()
    return ax


def _table_lines(model: PneumaticModel) -> list[str]:
    lines = [
        f"log: {model.meta.get('log', '-')}",
        f"robot: {model.meta.get('robot', '-')}",
        f"jacobian: {model.meta.get('jacobian', '-')}, starts: {model.meta.get('starts', '-')}",
        "",
    ]
    head = f"{'chamber':<22}" + "".join(f"{n:>8}" for n in NAMES) + f"{'rmse':>7}{'drift':>7}"
    lines.append(head)
    for name, c in model.chambers.items():
        v = c.params.vector()
        lines.append(
            f"{name[:21]:<22}"
            + "".join(f"{x:8.3g}" for x in v)
            + f"{c.raw.get('rmse', np.nan):7.2f}{100 * c.raw.get('drift_2s', np.nan):6.1f}%"
        )
        for t in c.params.terms:  # extra terms (diagnose's extended model)
            vals = ", ".join(f"{p.name} {p.value:.4g} ± {p.stderr:.2g} {p.unit}" for p in t.parameters)
            lines.append(f"{'':<4}+ {t.cause}: {vals}")
    skipped = model.meta.get("skipped") or {}
    if skipped:
        lines += ["", "not fitted:"] + [f"  {k}: {v}"[:110] for k, v in skipped.items()]
    return lines


def _typical(model: PneumaticModel) -> str:
    names = list(model.chambers)
    d = np.array([model.chambers[n].raw.get("drift_2s", np.nan) for n in names], float)
    return (
        names[int(np.nanargmin(np.abs(d - np.nanmedian(d))))] if np.isfinite(d).any() else names[0]
    )


def _chamber_data(model: PneumaticModel, log, name: str) -> ChamberData:
    c = model.chambers[name]
    return extract(log, name, c.volume_sensor, c.params.supply, c.params.room, check_span=False)


def pneumatic_pages(path: Path, pdf, context) -> None:
    model = load_model(path)
    lines = _table_lines(model)
    for start in range(0, len(lines), 80):
        save_page(
            pdf, text_page(f"Pneumatic models: {path.name}", lines[start : start + 80], fontsize=6)
        )
    fig, axes = page(2, 1, title="Multi-step prediction (§4.5.4)")
    plot_drift_curves(model, axes[0, 0])
    plot_drift_histogram(model, axes[1, 0])
    save_page(pdf, fig)
    sweep = _sweep(model)
    fig, axes = page(2, 1, title="Steady-state pressure (§4.3.1, §4.5.2)")
    plot_steady_state(model, sweep, ax=axes[0, 0])
    typical = sorted(model.chambers, key=lambda n: model.chambers[n].raw.get("drift_2s", 0))
    picks = [typical[0], typical[len(typical) // 2], typical[-1]]
    plot_steady_state(model, sweep, names=list(dict.fromkeys(picks)), ax=axes[1, 0])
    save_page(pdf, fig)
    log_path = Path(model.meta.get("log", ""))
    if not log_path.is_file():
        save_page(
            pdf, text_page("Pneumatic: fit log not found", [f"{log_path}: Fig. 4.11/4.12 need it"])
        )
        return
    log = load_log(log_path)
    name = _typical(model)
    data = _chamber_data(model, log, name)
    params = model.chambers[name].params
    t0 = float(data.time[0])
    fig, axes = page(2, 1, title=f"Next-step fit, {name} (median drift)")
    plot_delta_p(data, params, axes[0, 0], (t0, t0 + 10.0))
    plot_delta_p(data, params, axes[1, 0], (t0 + 2.0, t0 + 3.0))
    save_page(pdf, fig)
    pred = predict_with_resets(params, data)
    fig, axes = page(2, 1, title=f"Open-loop prediction, {name}")
    plot_integrated(data, params, pred, axes[0, 0], (t0, t0 + 10.0))
    plot_integrated(data, params, pred, axes[1, 0], (t0 + 2.0, t0 + 4.0))
    save_page(pdf, fig)


def _sweep(model: PneumaticModel):
    path = model.meta.get("steady_state_log")
    if not path or not Path(path).is_file():
        return None
    log = load_log(path)
    out = {}
    for name in model.chambers:
        try:
            out[name] = (log.stream("valve").column(name), log.stream("pressure").column(name))
        except DiegocalError:
            continue
    return out


def _recognise(path: Path) -> bool:
    return is_bundle(path, "pneumatic")


def _describe(path: Path) -> dict:
    meta = load_yaml(path).get("meta") or {}
    return {
        "log": meta.get("log"),
        "robot": meta.get("robot"),
        "command": meta.get("command"),
        "created": meta.get("created"),
    }


register_section(Section("pneumatic", _recognise, pneumatic_pages, _describe))
