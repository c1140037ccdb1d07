"""Report section for sgp/ model directories (thesis ch. 3; registers itself on import).

Recognises a directory holding ``sgp.yaml`` (one model), or a directory whose sub-directories
are models (a comparison of methods, e.g. ``results/{pr,gp,prgp,sgp}.sgp``), and the log that
``diegocal predict`` writes for such a model (held-out nMSE and ±2σ coverage per joint); other
logs are left to the log section. The words are in :mod:`.sgp_text`, the tables of what was fitted
in :mod:`.sgp_tables`, the figures in :mod:`.sgp_plots`.

Pages of a model: its opening in plain words, the per-joint table (nMSE in-sample and held-out,
±2σ coverage, the guard's choice, noise levels), the model's facts, the GP length-scales and the
identified parameters; then measured vs predicted torques with ±2σ bands on the training log and
on the held-out log; then thesis Fig. 3.10-style prediction ±2σ along each joint angle, with the
band's width below it, beside the latent std over a (q_j, qd_j) slice. A comparison opens with one
table over every model and joint. Figures flow: as many panels per page as fit, each page's panels
captioned below them.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from diegocal.io import load_log
from diegocal.report.layout import Column, Sheet, flow, split_axes, table_below, table_sheets
from diegocal.report.logs import LOG_SUFFIXES
from diegocal.report.registry import Section, register_section
from diegocal.report.sgp_plots import (
    angle_slice,
    plot_angle_slice,
    plot_heldout_band,
    plot_nmse_comparison,
    plot_prediction_band,
    plot_slice_width,
    plot_torque_band,
    plot_uncertainty_map,
    training_prediction,
)
from diegocal.report.sgp_tables import facts_rows, guard_table, lengthscale_table, parameter_table
from diegocal.report.sgp_text import (
    PREDICTION_NOTE,
    abstract,
    comparison_paragraph,
    headline,
    heldout,
    heldout_needs,
    heldout_score,
    joint_table,
    model_dirs,
    model_paragraphs,
    prediction_paragraphs,
    prediction_table,
    prismatic_joints,
)
from diegocal.report.style import save_page
from diegocal.sgp import load_model, load_summary

HEADING = "Torque model (SGP)"
PREDICTION_HEADING = "Held-out torque prediction"
BAND_HEIGHT = 0.19  # one joint's time series, fraction of the page
ROW_HEIGHT = 0.25  # one joint's slice (with its band's width) and uncertainty map


def recognise(path: Path) -> bool:
    return bool(model_dirs(path))


def describe(path: Path) -> dict:
    dirs = model_dirs(path)
    if len(dirs) == 1:
        return dict(load_summary(dirs[0]).get("meta") or {})
    logs = {str((load_summary(d).get("meta") or {}).get("log") or "") for d in dirs} - {""}
    return {"models": ", ".join(p.name for p in dirs), "log": logs.pop() if len(logs) == 1 else None}


# ----------------------------------------------------------------------------- captions
def band_caption(kind: str, where: str) -> str:
    text = (
        f"Measured torque (dark grey) and the model's mean prediction (blue) on the {where}; blue band: ±2σ of a "
        "measured torque (the model's uncertainty plus the sensor noise σ_v, thesis eq. 3.20; the parameters' share "
        "is the larger of eq. 3.20's and a cluster-robust one over 10 time blocks, which also holds the bias an effect "
        "the model lacks puts in them), which should hold 95 % of the measured torques."
    )
    if kind in ("sgp", "prgp"):
        text += (
            " Orange dashed: the parametric part alone (rigid body and friction, f(u)ŵ); where blue departs from it, "
            "the Gaussian process corrects it."
        )
    return text


def slice_caption(slices) -> str:
    """What a sheet of angle slices and uncertainty maps shows, and, joint by joint, how the band's
    width changes away from the training angles (thesis §3.5.1 expects it to grow there)."""
    return (
        "Left, top: the predicted torque along the joint's own angle, every other input held at its training mean "
        "(thesis Fig. 3.10); blue band: ±2 latent std, the model's uncertainty about the noise-free torque; grey "
        "ticks at the bottom: the angles seen in training. Left, bottom: the band's width (2 latent std) along the "
        "same angle, on an axis from zero; grey: the range of angles seen in training. Right: the latent std over "
        "the joint's angle and velocity, the other inputs at their training mean; white dots: the training samples. "
        "Thesis §3.5.1 expects the band to grow away from the data; here "
        + "; ".join(sl.words() for sl in slices)
        + "."
    )


def comparison_caption(models: list[Path], context) -> str:
    """What the nMSE bars show: hatched bars only when held-out bars stand beside them."""
    text = "nMSE (squared error over the measured torque's variance; log scale, lower is better) of each model"
    if all(heldout(m, context) is not None for m in models):
        return text + " on each joint: hatched, on the training log; solid, on the held-out log."
    return text + " on each joint, on the training log (no held-out log was given)."


# ----------------------------------------------------------------------------- pages
def model_pages(path: Path, sheets: list[Sheet], context, title: str, comparison: bool, last: bool = True) -> None:
    """One model's tables and figures, continuing on ``sheets`` (``last``: the section's last model)."""
    summary, model = load_summary(path), load_model(path)
    if comparison:
        if sheets[-1].room() < 0.3:
            sheets.append(Sheet(f"{title} (continued)"))
        sheets[-1].heading(f"Model {path.name}", size=12.5)
    for p in model_paragraphs(path, context):
        if not sheets[-1].paragraph(p):
            sheets.append(Sheet(f"{title} (continued)"))
            sheets[-1].paragraph(p)
    if not comparison:
        table_below(sheets, "Per joint", *joint_table([path], context), room=0.2, balance=False)
    facts = [Column("quantity", align="left"), Column("value", align="left"), Column("unit", align="left")]
    tables = [(f"How {path.name} was fitted", (facts, facts_rows(summary, model), ()))]
    tables += [("GP length-scales", lengthscale_table(summary)), ("The guard's cross-validation", guard_table(summary))]
    params = parameter_table(summary, prismatic_joints(model.robot))
    tables += [("Identified parameters", params if params[1] else None)]
    for name, table in tables:
        if table is not None:
            table_below(sheets, name, *table, room=0.2, balance=False)
    kind, n = model.options.kind, len(model.joint_names)
    pred = training_prediction(model)
    held = heldout(path, context)

    def bands(k, sheet, h):  # the training log, and beside it the held-out log when there is one
        if held is None:
            plot_torque_band(model, k, sheet.axes(h), pred=pred)
            return
        left, right = sheet.axes_row(h, 2, gap=0.08)
        plot_torque_band(model, k, left, pred=pred)
        plot_heldout_band(model, held, k, right)

    where = "training log" if held is None else "training log (left) and on the held-out log (right)"
    caption = band_caption(kind, where)
    if held is not None:
        caption += f" Held-out log: {Path(held.log).name}, which the model was not fitted on."
    flow(sheets, title, f"{path.name}: measured and predicted torque", caption, n, BAND_HEIGHT, bands)

    hyper = summary.get("hyperparameters") or {}
    gp = {j: kind != "pr" and (hyper.get(j) or {}).get("guard_choice") != "parametric" for j in model.joint_names}
    slices = [angle_slice(model, k, gp[j]) for k, j in enumerate(model.joint_names)]

    def row(k, sheet, h):
        left, right = sheet.axes_row(h, 2, gap=0.12, right=0.89)  # room for the colour bar's label
        top, bottom = split_axes(left)
        plot_angle_slice(slices[k], top)
        plot_slice_width(slices[k], bottom)
        plot_uncertainty_map(model, k, right)

    heading = f"{path.name}: uncertainty in state space (§3.5.1)"
    caption = lambda ks: slice_caption([slices[k] for k in ks])  # noqa: E731 - the joints a sheet shows
    flow(sheets, title, heading, caption, n, ROW_HEIGHT, row, last=last)


def pages(path: Path, pdf, context) -> None:
    dirs = model_dirs(path)
    title = f"{HEADING}: {Path(path).name}"
    sheets = [Sheet(title)]
    comparison = len(dirs) > 1
    if comparison:
        sheets[-1].paragraph(comparison_paragraph(dirs, context))
        table_below(sheets, "Comparison per model and joint", *joint_table(dirs, context), room=0.2, balance=False)
        flow(
            sheets,
            title,
            "nMSE per joint and model",
            comparison_caption(dirs, context),
            1,
            0.3,
            lambda k, sheet, h: plot_nmse_comparison(dirs, context, sheet.axes(h)),
        )
    for p in dirs:
        model_pages(p, sheets, context, title, comparison, last=p == dirs[-1])
    for sheet in sheets:
        save_page(pdf, sheet.fig)


# ----------------------------------------------------------------------------- predictions
def is_prediction(path: Path) -> bool:
    """A log written by ``diegocal predict`` for a dynamics model: predicted ``tau`` with its
    ``tau_std`` and the ``tau_measured`` it is scored against."""
    path = Path(path)
    if path.suffix.lower() not in LOG_SUFFIXES or not path.is_file():
        return False
    try:
        return all(load_log(path).has(s) for s in ("tau", "tau_std", "tau_measured"))
    except Exception:  # noqa: BLE001 - not a readable log: not ours
        return False


def _prediction(path: Path):
    log = load_log(path)
    return log, heldout_score(log)


def describe_prediction(path: Path) -> dict:
    """Title-page facts of a prediction log: what made it (Log.source; {} for a file made before
    predict recorded it)."""
    return dict(load_log(path).source or {})


def prediction_abstract(path: Path, context=None) -> list[str]:
    return prediction_paragraphs(path, *_prediction(path))


def prediction_headline(path: Path, context=None) -> str:
    _, sc = _prediction(path)
    return (
        f"{len(sc.channels)} joint(s), nMSE ≤ {np.max(sc.nmse):.2g}, "
        f"±2σ covers {100 * np.min(sc.coverage):.0f}-{100 * np.max(sc.coverage):.0f} %"
    )


def prediction_pages(path: Path, pdf, context) -> None:
    """A prediction log: opening in plain words, per joint held-out nMSE, RMSE and ±2σ coverage
    (0.95 expected for a calibrated predictive std), then measured vs predicted with the band."""
    log, sc = _prediction(path)
    title = f"{PREDICTION_HEADING}: {Path(path).name}"
    columns, rows = prediction_table(sc)
    sheets = table_sheets(title, columns, rows, intro=prediction_paragraphs(path, log, sc), notes=(PREDICTION_NOTE,))
    flow(
        sheets,
        title,
        "Measured and predicted torque",
        "Measured torque (dark grey) and the predicted mean (blue) over the log's time; blue band: the predicted "
        "±2σ of a measured torque (model uncertainty plus sensor noise, thesis eq. 3.20), which should hold 95 % of "
        "the measured torques.",
        len(sc.channels),
        BAND_HEIGHT,
        lambda k, sheet, h: plot_prediction_band(log, k, sheet.axes(h), sc=sc),
        last=True,
    )
    for sheet in sheets:
        save_page(pdf, sheet.fig)


register_section(
    Section(
        "sgp",
        recognise,
        pages,
        describe,
        heading=HEADING,
        abstract=abstract,
        headline=headline,
        heldout_needs=heldout_needs,
    )
)
# a dynamics prediction is a log too: tried before the plain log section
register_section(
    Section(
        "sgp prediction",
        is_prediction,
        prediction_pages,
        describe_prediction,
        heading=PREDICTION_HEADING,
        abstract=prediction_abstract,
        headline=prediction_headline,
    ),
    before="log",
)
