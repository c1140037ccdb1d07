"""Report section for pneumatic.yaml (thesis ch. 4; registers itself on import).

Pages: an opening in plain words with the key numbers and Table 4.1 (what c1..c9 mean, their
units and bounds); the fitted parameters of every chamber with the next-step error and the 2-s
drift, split across pages; Fig. 4.13 (drift of open-loop prediction against horizon, all chambers,
on the fit log and on held-out logs given with ``--heldout``, both at the logs' full rate when the
fit log is at hand); Fig. 4.10 (steady-state curves: fitted s(u) and, when the fit recorded a
locked-cylinder sweep log, the measured sweep); Fig. 4.11 (next-step Δp overlay) and Fig. 4.12
(pressure integrated from grid points) for a typical chamber, rebuilt from the fit log. The plots
are in :mod:`diegocal.report.pneumatic_plots`.
"""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np

from diegocal.errors import DiegocalError
from diegocal.io import load_log, load_yaml
from diegocal.pneumatic.data import ChamberData, extract
from diegocal.pneumatic.files import PneumaticModel, load_model
from diegocal.pneumatic.params import SPECS
from diegocal.pneumatic.predict import HORIZON_S, Drift, drift, predict_with_resets
from diegocal.report.layout import Column, Sheet, table_sheets
from diegocal.report.pneumatic_plots import (
    UNIT,
    plot_delta_p,
    plot_drift_curves,
    plot_drift_histogram,
    plot_integrated,
    plot_steady_state,
    step_words,
    stored_drift,
)
from diegocal.report.registry import ReportContext, Section, is_bundle, register_section
from diegocal.report.style import save_page

#: The streams a held-out log needs: the chambers' pressure and valve command, their volume sensor.
HELDOUT_STREAMS = ("pressure", "valve", "pots")


# ----------------------------------------------------------------------------- drift, words, tables
def _drift_on(model: PneumaticModel, log) -> dict[str, Drift]:
    """{chamber: Drift} of every chamber whose data the log holds, at the log's full rate."""
    out = {}
    for name in model.chambers:
        try:
            out[name] = drift(model.chambers[name].params, _chamber_data(model, log, name))
        except DiegocalError:
            continue
    return out


@functools.lru_cache(maxsize=4)
def heldout_drift(path: str, heldout: tuple[str, ...]) -> tuple[str | None, dict]:
    """(held-out log, {chamber: Drift}) on the first held-out log that has the chambers' data."""
    model = load_model(path)
    for hpath in ReportContext(heldout=tuple(map(Path, heldout))).heldout_for(_robot_name(model), HELDOUT_STREAMS):
        out = _drift_on(model, load_log(hpath))
        if out:
            return str(hpath), out
    return None, {}


@functools.lru_cache(maxsize=4)
def fit_drift(path: str) -> dict[str, Drift]:
    """{chamber: Drift} on the fit log, recomputed at its full rate (as the held-out one is) when
    the log is at hand; else the curves pneumatic.yaml stores, a point every ``curve_step_s``."""
    model = load_model(path)
    log_path = Path(str(model.meta.get("log", "")))
    out = _drift_on(model, load_log(log_path)) if log_path.is_file() else {}
    return out or stored_drift(model)


def _robot_name(model: PneumaticModel) -> str | None:
    rec = model.meta.get("robot")
    return Path(str(rec)).name if rec else None


def _drifts(model: PneumaticModel) -> np.ndarray:
    return 100 * np.array([c.raw.get("drift_2s", np.nan) for c in model.chambers.values()], float)


def _heldout(path: Path, context) -> tuple[str | None, dict]:
    return heldout_drift(str(Path(path).resolve()), tuple(str(p) for p in context.heldout))


def abstract(path: Path, context) -> list[str]:
    """The section's opening in plain words."""
    model = load_model(path)
    d = _drifts(model)
    d = d[np.isfinite(d)]
    n = len(model.chambers)
    samples = sorted({int(c.raw.get("n_samples", 0)) for c in model.chambers.values()})
    log = Path(str(model.meta.get("log", "?"))).name
    text = (
        f"The 9-parameter valve-chamber model (thesis eq. 4.10, Table 4.1) was fitted to each of {n} chambers "
        f"by next-step least squares on {log} ({'/'.join(map(str, samples))} samples per chamber). Predicting the "
        f"pressure open loop from the valve command and the joint motion, 2 s after the last measured pressure the "
        f"error is {np.median(d):.1f} % of Pc − Pr for the median chamber and {d.max():.1f} % for the worst "
        f"on the fit log; {(d < 4).sum()} of {d.size} chambers stay under the thesis's usual 4 %, "
        f"{(d < 10).sum()} under its 10 % bound."
    )
    hpath, held = _heldout(path, context)
    if held:
        h = np.array([x.final for x in held.values()]) * 100
        text += (
            f" On held-out data ({Path(hpath).name}, {len(held)} chambers) the 2-s drift is {np.median(h):.1f} % "
            f"for the median chamber and {h.max():.1f} % for the worst; {(h < 4).sum()} under 4 %, "
            f"{(h < 10).sum()} under 10 %."
        )
    else:
        text += " No held-out log was given (diegocal report ... --heldout LOG)."
    out = [text]
    names, drift = list(model.chambers), _drifts(model)
    # open: the chambers beyond the thesis's usual 4 % (at most three, the worst first)
    worst = [f"{names[k]} ({drift[k]:.1f} %)" for k in np.argsort(-drift)[:3] if drift[k] >= 4.0]
    skipped = model.meta.get("skipped") or {}
    beyond = int((drift >= 4.0).sum())
    which = "are" if beyond == len(worst) else f"are {beyond}, the worst"
    wrong = [f"the chambers that drift beyond 4 % on the fit's own log {which} {', '.join(worst)}"] if worst else []
    if skipped:
        wrong.append(f"{len(skipped)} chamber(s) not fitted: " + "; ".join(f"{k}: {v}" for k, v in skipped.items()))
    extra = sorted({t.cause for c in model.chambers.values() for t in c.params.terms})
    if extra:
        wrong.append("the model carries terms beyond eq. 4.10 found by diagnose: " + ", ".join(extra))
    if wrong:
        out.append("Still open: " + "; ".join(wrong) + ".")
    return out


def headline(path: Path, context) -> str:
    model = load_model(path)
    d = _drifts(model)
    text = f"{len(model.chambers)} chambers; 2-s drift median {np.nanmedian(d):.1f} %, worst {np.nanmax(d):.1f} %"
    text += " (fit log)"
    _, held = _heldout(path, context)
    if held:
        h = 100 * np.array([x.final for x in held.values()])
        text += f", {np.median(h):.1f} % / {h.max():.1f} % held-out"
    return text + f"; {(d < 4).sum()} of {d.size} under 4 %"


def parameter_table(model: PneumaticModel, held: dict) -> tuple[list[Column], list[list]]:
    """One row per chamber: c1..c9 with Table 4.1's units, next-step RMSE and 2-s drift."""
    columns = [Column("chamber", align="left")]
    columns += [Column(spec.name, _unit(spec.unit)) for spec in SPECS]
    columns += [Column("next-step\nRMSE", UNIT), Column("2-s drift\nfit log", "%")]
    if held:
        columns.append(Column("2-s drift\nheld-out", "%"))
    rows = []
    for name, c in model.chambers.items():
        row = [name] + [f"{x:.3g}" for x in c.params.vector()]
        row += [f"{c.raw.get('rmse', np.nan):.3g}", f"{100 * c.raw.get('drift_2s', np.nan):.1f}"]
        if held:
            row.append(f"{100 * held[name].final:.1f}" if name in held else "–")
        rows.append(row)
    return columns, rows


def _unit(unit: str) -> str:
    return unit.replace("pu", UNIT).replace("^3", "³")


def table41() -> tuple[list[Column], list[list]]:
    """Thesis Table 4.1: what each parameter means, its unit and the bounds of the fit."""
    columns = [
        Column("parameter", align="left"),
        Column("meaning (thesis Table 4.1)", align="left"),
        Column("unit", align="left"),
        Column("bounds", align="left"),
    ]
    rows = []
    for spec in SPECS:
        lo = "" if not np.isfinite(spec.lower) else f"{spec.lower:g} < "
        hi = "" if not np.isfinite(spec.upper) else f" < {spec.upper:g}"
        rows.append([spec.name, spec.meaning, _unit(spec.unit), f"{lo}{spec.name}{hi}" if lo or hi else "–"])
    return columns, rows


TABLE_NOTES = (
    "u is the valve command in V; v the volume sensor (the joint's pot) centred and scaled to [-1, 1] on the fit "
    "log, so c4..c6 are per unit of that normalised reading. c_b = (Pc + Pr)/2 and c_s = (Pc − Pr)/2 come from "
    "the supply and room pressures in sensors.yaml, c_γ = 0.1 V is fixed (§4.4). Next-step RMSE: error of the "
    "one-step prediction the fit minimises, on the fit log. 2-s drift: RMS error 2 s after the last measured "
    "pressure, in % of Pc − Pr. Standard errors are in pneumatic.yaml; one written as nan there is not determined "
    "by the data (the fit's Jacobian is rank-deficient along that parameter).",
)


def _typical(model: PneumaticModel) -> str:
    names = list(model.chambers)
    d = np.array([model.chambers[n].raw.get("drift_2s", np.nan) for n in names], float)
    return names[int(np.nanargmin(np.abs(d - np.nanmedian(d))))] if np.isfinite(d).any() else names[0]


def _chamber_data(model: PneumaticModel, log, name: str) -> ChamberData:
    c = model.chambers[name]
    return extract(log, name, c.volume_sensor, c.params.supply, c.params.room, check_span=False)


def pneumatic_pages(path: Path, pdf, context) -> None:
    model = load_model(path)
    hpath, held = _heldout(path, context)
    title = f"Pneumatic valve-chamber models: {path.name}"
    key = [Column("quantity", align="left"), Column("value"), Column("unit", align="left")]
    sheets = table_sheets(title, key, _key_rows(model, hpath, held), intro=abstract(path, context))
    sheets[-1:] = table_sheets("The nine parameters", *table41(), sheet=sheets[-1])
    sheets += table_sheets("Fitted parameters per chamber", *parameter_table(model, held), notes=TABLE_NOTES, size=7)
    extra = [(n, t) for n, c in model.chambers.items() for t in c.params.terms]
    if extra:
        cols = [Column("chamber", align="left"), Column("term", align="left"), Column("fitted values", align="left")]
        rows = [
            [n, t.cause, ", ".join(f"{p.name} {p.value:.4g} ± {p.stderr:.2g} {p.unit}" for p in t.parameters)]
            for n, t in extra
        ]
        sheets += table_sheets("Terms beyond eq. 4.10 (from diagnose)", cols, rows)
    for sheet in sheets:
        save_page(pdf, sheet.fig)

    fit = fit_drift(str(Path(path).resolve()))
    if fit:  # a fit with drift_starts = 0 measured none
        sheet = Sheet(f"{title}: multi-step prediction (§4.5.4)")
        plot_drift_curves(fit, sheet.axes(0.36), held)
        plot_drift_histogram(model, sheet.axes(0.3), held)
        sheet.caption(drift_caption(fit, held))
        save_page(pdf, sheet.fig)

    sweep = _sweep(model)
    sheet = Sheet(f"{title}: steady-state pressure (§4.3.1, §4.5.2)")
    plot_steady_state(model, sweep, ax=sheet.axes(0.36))
    ranked = sorted(model.chambers, key=lambda n: model.chambers[n].raw.get("drift_2s", 0))
    picks = list(dict.fromkeys([ranked[0], _typical(model), ranked[-1]]))  # the median: the next page's chamber
    plot_steady_state(model, sweep, names=picks, ax=sheet.axes(0.3))
    sheet.caption(
        "The pressure each chamber settles to at a constant valve command with the joint at rest (mid travel, "
        "v̇ = 0), from the fitted c1..c3 (eq. 4.10a-c). Top: every chamber. Bottom: the chambers with the smallest, "
        "the median and the largest 2-s drift."
        + (" Dots: the measured locked-cylinder sweep." if sweep else " No locked-cylinder sweep was recorded.")
    )
    save_page(pdf, sheet.fig)

    log_path = Path(str(model.meta.get("log", "")))
    if not log_path.is_file():
        return
    log = load_log(log_path)
    name = _typical(model)
    data = _chamber_data(model, log, name)
    params = model.chambers[name].params
    t0 = float(data.time[0])
    sheet = Sheet(f"{title}: one chamber, {name} (median drift)")
    plot_delta_p(data, params, sheet.axes(0.16), (t0, t0 + 10.0))
    plot_delta_p(data, params, sheet.axes(0.16), (t0 + 2.0, t0 + 3.0))
    pred = predict_with_resets(params, data)
    plot_integrated(data, params, pred, sheet.axes(0.16), (t0, t0 + 10.0))
    plot_integrated(data, params, pred, sheet.axes(0.16), (t0 + 2.0, t0 + 4.0))
    sheet.caption(
        "Top two: the change of pressure over one step, measured (grey) and predicted by the model from the measured "
        "pressure (blue), the quantity the fit minimises (Fig. 4.11); the second zooms into one second. Bottom two: "
        f"the pressure integrated open loop (blue), re-initialised with the measured pressure (grey) at the dotted "
        f"lines, every {HORIZON_S:g} s (Fig. 4.12)."
    )
    save_page(pdf, sheet.fig)


def drift_caption(fit: dict[str, Drift], held: dict) -> str:
    """What the drift page shows: how many starts, at which step, which logs."""
    starts = next(iter(fit.values())).n_starts
    text = (
        f"From {starts or 'the'} evenly spaced start points per chamber the pressure is predicted open "
        "loop from the measured valve command and joint motion and compared with the measured pressure. Top: RMS "
        "error against the time since the last measured pressure, in % of Pc − Pr (the thesis plots the same in "
        f"units of (Pc − Pr)/10), {step_words(fit)}; thin blue lines one chamber each on the fit log, the black line "
        "all chambers pooled"
    )
    text += ", the orange line all chambers pooled on the held-out log at the same points in time." if held else "."
    return text + (
        f" Bottom: the error at {HORIZON_S:g} s, one count per chamber. Red lines: the thesis's drift levels, 'less "
        "than 10 % ... and usually less than 4 %'."
    )


def _key_rows(model: PneumaticModel, hpath, held: dict) -> list[list]:
    d = _drifts(model)
    rmse = np.array([c.raw.get("rmse", np.nan) for c in model.chambers.values()], float)
    rows = [
        ["fit log", Path(str(model.meta.get("log", "–"))).name, ""],
        ["chambers fitted", len(model.chambers), ""],
        ["chambers not fitted", len(model.meta.get("skipped") or {}), ""],
        ["next-step RMSE, median chamber (fit log)", f"{np.nanmedian(rmse):.3g}", UNIT],
        ["2-s drift, median / worst chamber (fit log)", f"{np.nanmedian(d):.1f} / {np.nanmax(d):.1f}", "% of Pc − Pr"],
        ["chambers under 4 % / under 10 % (fit log)", f"{(d < 4).sum()} / {(d < 10).sum()}", ""],
    ]
    if held:
        h = 100 * np.array([x.final for x in held.values()])
        rows += [
            ["held-out log", Path(hpath).name, ""],
            ["2-s drift, median / worst chamber (held-out)", f"{np.median(h):.1f} / {h.max():.1f}", "% of Pc − Pr"],
            ["chambers under 4 % / under 10 % (held-out)", f"{(h < 4).sum()} / {(h < 10).sum()}", ""],
        ]
    return rows


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
    return is_bundle(path, "pneumatics")


def _describe(path: Path) -> dict:
    meta = load_yaml(path).get("meta") or {}
    return {
        "log": meta.get("log"),
        "robot": meta.get("robot"),
        "command": meta.get("command"),
        "created": meta.get("created"),
    }


register_section(
    Section(
        "pneumatic",
        _recognise,
        pneumatic_pages,
        _describe,
        heading="Pneumatic valve-chamber models",
        abstract=abstract,
        headline=headline,
        heldout_needs=lambda path: [(_robot_name(load_model(path)), HELDOUT_STREAMS)],
    )
)
