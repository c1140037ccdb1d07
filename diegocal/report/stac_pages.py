"""The STAC section as a document (calib.yaml; the plots are in :mod:`diegocal.report.stac_plots`).

Pages: an opening in plain words with the key numbers (fit log, convergence, noise levels,
residuals at the fitted joint angles, held-out prediction error); the pot and marker tables with
units and standard errors; the markers on the robot and the convergence; the residual histograms.

Residuals need the joint angles of every frame: read from the log stac wrote with
``--joint-angles`` when the calibration names one, otherwise tracked again here (the q-phase of
eq. 2.21 from pots and markers with the calibration fixed). Held-out logs come from
``diegocal report --heldout LOG``: joint angles tracked from the pots alone predict the markers
(thesis §2.7.2, Table 2.1).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from diegocal.errors import DiegocalError
from diegocal.io import load_log
from diegocal.io.bundle import load_bundle
from diegocal.report.layout import Column, Sheet, table_below, table_sheets
from diegocal.report.registry import ReportContext
from diegocal.report.stac_plots import (
    plot_cost,
    plot_markers_on_robot,
    plot_residual_hist,
    plot_sigma,
    residuals_by_type,
    skeleton,
)
from diegocal.report.stac_words import MM, estimated_words, held_words, kinds_of, milli, sigma_words
from diegocal.report.style import save_page
from diegocal.robot import load_robot, resolve_robot_dir
from diegocal.stac.calibration import POT_UNITS, READING_UNITS, Calibration
from diegocal.stac.predict import predict
from diegocal.stac.result import StacOptions
from diegocal.stac.terms import apply_terms

#: The streams a held-out log needs: markers predicted from the pots alone.
HELDOUT_STREAMS = ("pots", "markers")


@dataclass(frozen=True)
class Evaluation:
    """What the report measures of a calibration: residuals on its own log, held-out errors.

    residuals : {type: (residuals (N,), unit)} at the fitted joint angles (markers: distance, m)
    heldout : [(log path, frames, {target: MAE})] markers predicted from the pots alone
    heldout_errors : (N,) per-sample marker distances on the first held-out log, m
    """

    fit_log: str | None
    frames: int | None
    duration: float | None
    residuals: dict
    heldout: tuple
    heldout_errors: np.ndarray | None
    note: str = ""


def _bundle(path: Path):
    return load_bundle(path)


def _calibration(path: Path):
    return Calibration.from_dict(_bundle(path).data, source=str(path))


def _robot(path: Path, context):
    rec = _bundle(path).robot
    rdir = context.robot or rec["dir"]
    if rdir is None or not Path(rdir).is_dir():
        rdir = resolve_robot_dir(rec["name"], None) if rec["name"] else None
    return load_robot(rdir) if rdir is not None else None


@functools.lru_cache(maxsize=4)
def evaluate(path: str, robot_dir: str | None, heldout: tuple[str, ...]) -> Evaluation:
    """Residuals and held-out errors of the calibration at ``path`` (cached: the summary page and the
    section both ask)."""
    context = ReportContext(robot=Path(robot_dir) if robot_dir else None, heldout=tuple(map(Path, heldout)))
    cal, bundle = _calibration(Path(path)), _bundle(Path(path))
    try:
        robot = _robot(Path(path), context)
    except DiegocalError as exc:
        return Evaluation(bundle.log, None, None, {}, (), None, f"robot not found ({exc})")
    if robot is None:
        return Evaluation(bundle.log, None, None, {}, (), None, "the calibration names no robot directory")
    residuals, frames, duration, note = {}, None, None, ""
    options = StacOptions(quiet=True)
    if bundle.log and Path(bundle.log).is_file():
        log = load_log(bundle.log).without_truth()
        frames, duration = log.n_samples, log.duration
        q = _joint_angles(bundle.data, log)
        try:
            if q is None:  # track again: the q-phase from every sensor, the calibration fixed
                q = predict(log, robot, cal, ("pots", "markers"), ("markers",), options).q
            if cal.terms:  # an extended calibration: its terms map the log and the robot first
                applied = apply_terms(cal.terms, log, robot)
                residuals = residuals_by_type(replace(cal, terms=()), applied.robot, applied.log, q)
            else:
                residuals = residuals_by_type(cal, robot, log, q)
        except DiegocalError as exc:
            note = f"residuals not computed ({exc})"
    else:
        note = f"the fit log {bundle.log} is not found: no residuals"
    held, errors = [], None
    for hpath in context.heldout_for(bundle.robot, HELDOUT_STREAMS):
        try:
            hlog = load_log(hpath).without_truth()
            pred = predict(hlog, robot, cal, ("pots",), ("markers",), options)
        except DiegocalError:
            continue
        held.append((str(hpath), hlog.n_samples, dict(pred.mae)))
        if errors is None:
            idx = [hlog.streams["markers"].names.index(n) for n in pred.marker_names]
            d = np.linalg.norm(pred.markers - hlog.streams["markers"].data[:, idx], axis=-1)
            errors = d[np.isfinite(d)]
    return Evaluation(bundle.log, frames, duration, residuals, tuple(held), errors, note)


def _joint_angles(raw: dict, log):
    """The tracked q stac wrote on request (``--joint-angles``), if it matches the log."""
    path = (raw.get("meta") or {}).get("joint_angles") or raw.get("joint_angles")
    if not path or not Path(path).is_file():
        return None
    qlog = load_log(path)
    return qlog.streams["q"].data if qlog.has("q") and qlog.n_samples == log.n_samples else None


def _evaluation(path: Path, context) -> Evaluation:
    robot = str(context.robot) if context.robot else None
    return evaluate(str(Path(path).resolve()), robot, tuple(str(p) for p in context.heldout))


def _rms(r) -> float:
    return float(np.sqrt(np.mean(np.square(r)))) if len(r) else float("nan")


# ----------------------------------------------------------------------------- words
def abstract(path: Path, context) -> list[str]:
    """The section's opening in plain words."""
    cal, ev = _calibration(path), _evaluation(path, context)
    log = Path(ev.fit_log).name if ev.fit_log else "an unnamed log"
    span = f" ({ev.frames} frames, {ev.duration:.3g} s)" if ev.frames else ""
    conv = "converged" if cal.fit.converged else "stopped before converging"
    try:
        robot = _robot(path, context) if not cal.pot_units else None
    except DiegocalError:
        robot = None
    text = (
        f"STAC (thesis ch. 2) calibrated {len(cal.pot_names)} pots, the positions of "
        f"{len(cal.marker_names)} markers on their links and the mocap frame from {log}{span}; it {conv} after "
        f"{cal.fit.iterations} iterations ({cal.fit.seconds:.1f} s). {estimated_words(cal, robot)}"
    ).rstrip()
    if ev.residuals:
        parts = [_residual_words(g, r, u) for g, (r, u) in ev.residuals.items()]
        text += " At the fitted joint angles the residuals are " + ", ".join(parts) + "."
    held = _heldout_words(ev, _bundle(path).data.get("prediction") or [])
    paragraphs = [f"{text} {held}" if held else text]
    wrong = held_words(cal, robot)
    turned = gauge_markers(cal)
    if turned:
        wrong.append(
            f"the positions of {', '.join(turned)} are placed turned about their joint's axis by whatever error that "
            "nominal bias leaves: their distance from the axis and their place along it are the data's, their "
            "angle about it is the convention's, and their ± hold in it"
        )
    if not cal.fit.converged:
        wrong.append("the fit did not converge: raise --max-iterations")
    if ev.note:
        wrong.append(ev.note)
    if wrong:
        paragraphs.append("What the data leave open: " + "; ".join(wrong) + ".")
    return paragraphs


def headline(path: Path, context) -> str:
    """One line: what was calibrated and how well, on the fit log and held-out."""
    cal, ev = _calibration(path), _evaluation(path, context)
    text = f"{len(cal.pot_names)} pots, {len(cal.marker_names)} markers"
    if "markers" in ev.residuals:
        text += f"; marker residual {MM * _rms(ev.residuals['markers'][0]):.2f} mm RMS"
    if ev.heldout:
        text += f"; held-out markers from pots {MM * ev.heldout[0][2].get('markers', np.nan):.2f} mm MAE"
    unobservable = [n for n, r in cal.pot_roles().items() if r[1] == "unobservable"]
    if unobservable:
        text += f"; {len(unobservable)} pot(s) unobservable"
    return text


def _residual_words(group: str, r, unit: str) -> str:
    value, shown = milli(_rms(r), unit)
    if group == "markers":
        return f"{group} {value:.2f} {shown} RMS distance ({len(r)} samples)"
    what = "encoders" if group == "encoder" else f"{group} pots"
    return f"{what} {value:.3g} {shown} RMS ({len(r)} samples)"


def _heldout_words(ev: Evaluation, recorded: list) -> str:
    """The held-out result in words: scored here on --heldout logs, else the MAE rows older versions of
    `diegocal predict` recorded in calib.yaml (``prediction``)."""
    rows = list(ev.heldout)
    recorded = [r for r in recorded if isinstance(r, dict) and "markers" in (r.get("mae") or {})]
    if not rows and recorded:
        return (
            "Held-out prediction recorded in the file: "
            + "; ".join(
                f"from {'+'.join(r.get('from', []))} to markers {MM * r['mae']['markers']:.2f} mm" for r in recorded
            )
            + "."
        )
    if not rows:
        return (
            "No held-out log was given (diegocal report ... --heldout LOG): the errors above are on the fit's own data."
        )
    fit = ev.residuals.get("markers")
    parts = []
    for k, (p, frames, mae) in enumerate(rows):
        what = "the markers predicted from the pots alone lie " if k == 0 else ""
        where = " (mean) from where the cameras saw them" if k == 0 else ""
        parts.append(f"on {Path(p).name} ({frames} frames) {what}{MM * mae.get('markers', np.nan):.2f} mm{where}")
    text = "Held-out test (thesis Table 2.1; joint angles tracked from the pots, no marker used): " + "; ".join(parts)
    if fit is not None:
        ratio = rows[0][2].get("markers", np.nan) / max(np.mean(fit[0]), 1e-12)
        text += f", {ratio:.1f} times the mean marker residual of the fit itself ({MM * np.mean(fit[0]):.2f} mm)" + (
            ": the calibration carries over to new data" if ratio < 2 else ": part of it does not carry over"
        )
    return text + "."


# ----------------------------------------------------------------------------- tables
def key_rows(cal, ev: Evaluation) -> list[list]:
    rows = [["fit log", Path(ev.fit_log).name if ev.fit_log else "–", ""]]
    if ev.frames:
        rows += [["frames (samples)", ev.frames, ""], ["duration", f"{ev.duration:.3g}", "s"]]
    rows += [
        ["method", cal.method, ""],
        ["iterations", cal.fit.iterations, ""],
        ["converged", "yes" if cal.fit.converged else "no", ""],
    ]
    unresolved = {u.get("group") for u in cal.sigma_unresolved}
    for g, v in cal.sigma_by_group.items():
        how = "not resolved: its detection limit" if g in unresolved else "estimated"
        value, unit = milli(v, READING_UNITS.get(g, "sensor unit"))
        rows.append([f"noise σ, {g} ({how}, §2.3.5)", f"{value:.3g}", unit])
    for g, (r, unit) in ev.residuals.items():
        value, unit = milli(_rms(r), unit)
        rows.append([f"residual RMS, {g} ({len(r)} samples)", f"{value:.3g}", unit])
    for p, frames, mae in ev.heldout:
        for t, v in mae.items():
            what = f"held-out MAE, {t} from pots: {Path(p).name} ({frames} frames)"
            value, unit = milli(v, READING_UNITS.get(t, "sensor unit"))
            rows.append([what, f"{value:.3g}", unit])
    angle = np.degrees(np.arccos(np.clip((np.trace(cal.mocap_R) - 1) / 2, -1, 1)))
    rows.append(["mocap frame: rotation from the base link", f"{angle:.1f}", "deg"])
    rows.append(["mocap frame: translation", ", ".join(f"{x:.3f}" for x in cal.mocap_T), "m"])
    return rows


def pot_table(cal, robot) -> tuple[list[Column], list[list], list[str]]:
    kinds = kinds_of(robot)
    roles = cal.pot_roles(kinds)
    gse = cal.gain_se if cal.gain_se is not None else np.full(len(cal.gain), np.nan)
    bse = cal.bias_se if cal.bias_se is not None else np.full(len(cal.gain), np.nan)
    columns = [
        Column("pot", align="left"),
        Column("kind", align="left"),
        Column("gain"),
        Column("± SE"),
        Column("gain unit", align="left"),
        Column("bias"),
        Column("± SE"),
        Column("bias unit", align="left"),
        Column("note", align="left"),
    ]
    rows = []
    gauge_joints = {g.get("joint") for g in cal.gauges} - {None}
    spans = {p.name: set(p.joints) for p in robot.sensors.pots} if robot is not None else {}
    for i, n in enumerate(cal.pot_names):
        gain_role, bias_role = roles[n]
        note = {"unobservable": "nominal: unobservable", "gauge": "bias nominal: gauge"}.get(bias_role, "")
        if gain_role == "design":
            note = "; ".join(x for x in ("gain 1 by design", note) if x)
        if not note and len(spans.get(n, ())) > 1 and spans[n] & gauge_joints:
            note = f"bias in {', '.join(sorted(spans[n] & gauge_joints))}'s zero"
        kind = kinds.get(n, "")
        units = cal.pot_units[i] if i < len(cal.pot_units) else POT_UNITS.get(kind, ("V per unit", "V"))
        gain = [f"{cal.gain[i]:.5g}", _se(gse[i]), units[0]]
        rows.append([n, kind, *gain, f"{cal.bias[i]:.4f}", _se(bse[i]), units[1], note])
    notes = [
        "Reading = gain · (joint angle, rad, or anchor distance / tendon excursion, m) + bias (thesis eq. 2.18-2.20); "
        "an encoder reads its joint's own coordinate (rad), so its gain is 1 by design and its bias is in rad. "
        f"± SE: one standard error, {se_method_words(cal)}. A dash means not estimated: "
        "'bias nominal: gauge' pots read a joint whose zero the markers cannot fix (rotating the markers on the "
        "joint's link, or the mocap frame for a joint turning every marker about an axis fixed in the base, "
        "absorbs any offset), so the bias keeps its sensors.yaml value; 'nominal: unobservable' pots read "
        "joints no marker moves with, so gain and bias both keep their sensors.yaml values. 'bias in J's zero': a "
        "tendon over the gauge joint J reads J's angle too, so its bias holds J's nominal zero (compare it with "
        "another calibration of the same convention only)."
    ]
    return columns, rows, notes


def se_method_words(cal) -> str:
    """How the calibration's standard errors were estimated, from calib.yaml's ``stderr`` record."""
    how = getattr(cal, "stderr", None) or {}
    if how.get("method") == "block_sandwich":
        blocks = f" over {how['blocks']} contiguous blocks of frames" if how.get("blocks") else ""
        return (f"the larger of the model-based one (eq. 2.21's information) and a cluster-robust sandwich{blocks} "
                "(the residuals are correlated in time)")
    return "from the fit's Fisher information (eq. 2.21)"


def gauge_markers(cal) -> dict:
    """{marker: joint} of the markers a leaf gauge turns with its joint's zero (calib.yaml's
    ``gauges[].markers``)."""
    return {m: g["joint"] for g in getattr(cal, "gauges", ()) or () for m in g.get("markers") or ()}


def marker_table(cal, robot) -> tuple[list[Column], list[list], list[str]]:
    nominal = {m.name: np.asarray(m.xyz, float) for m in robot.sensors.markers} if robot is not None else {}
    se = cal.marker_xyz_se if cal.marker_xyz_se is not None else np.full_like(cal.marker_xyz, np.nan)
    columns = [
        Column("marker", align="left"),
        Column("link", align="left"),
        Column("x", "mm"),
        Column("y", "mm"),
        Column("z", "mm"),
        Column("± SE (largest axis)", "mm"),
        Column("moved from the seed", "mm"),
        Column("note", align="left"),
    ]
    rows, turned = [], gauge_markers(cal)
    for i, n in enumerate(cal.marker_names):
        xyz = cal.marker_xyz[i]
        moved = MM * np.linalg.norm(xyz - nominal[n]) if n in nominal else None
        s = np.nanmax(se[i]) if np.isfinite(se[i]).any() else np.nan
        shift = "–" if moved is None else f"{moved:.1f}"
        note = f"gauge: {turned[n]}" if n in turned else ""
        rows.append([n, cal.marker_links[i], *(f"{MM * v:.1f}" for v in xyz), _se(MM * s, 2), shift, note])
    notes = [
        "Marker positions in their link's frame (thesis eq. 2.10's d_i). 'Moved from the seed': distance from the "
        "position sensors.yaml gives, the calibration's starting point. 'gauge: J': the marker rides on the link "
        "of joint J, whose zero the markers cannot fix: its angle about J's axis follows the pot bias held at "
        "nominal, and its ± hold in that convention (its distance from the axis and its place along it are the "
        "data's)."
    ]
    return columns, rows, notes


def _se(v, digits: int = 2) -> str:
    return "–" if not np.isfinite(v) else f"{v:.{digits}g}"


# ----------------------------------------------------------------------------- pages
def pages(path: Path, pdf, context) -> None:
    cal, ev = _calibration(path), _evaluation(path, context)
    try:
        robot = _robot(path, context)
    except DiegocalError:
        robot = None
    title = f"Kinematic calibration (STAC): {path.name}"
    key = [Column("quantity", align="left"), Column("value"), Column("unit", align="left")]
    sheets = table_sheets(title, key, key_rows(cal, ev), intro=abstract(path, context))
    table_below(sheets, "Pot gains and biases", *pot_table(cal, robot))
    table_below(sheets, "Marker positions", *marker_table(cal, robot))
    for sheet in sheets:
        save_page(pdf, sheet.fig)

    sheet = Sheet(f"{title}: markers and convergence")
    if robot is not None:
        sk = skeleton(cal, robot)
        side, front = sheet.axes_row(0.38, 2)
        plot_markers_on_robot(sk, side, (0, 2))
        plot_markers_on_robot(sk, front, (1, 2))
        for ax in (side, front):  # the caption says what the symbols are; a legend would cover markers
            ax.get_legend().remove()
            ax.set_aspect("equal", adjustable="datalim")
        side.set_title(f"side view, {len(cal.marker_names)} markers (Figs. 2.8-2.9)")
        front.set_title("front view")
        sheet.caption(
            "The robot at its neutral pose (grey: links between joint origins). Open orange circles: the seed, the "
            "origin of each marker's link; filled blue: the calibrated marker positions; the thin blue line joins "
            "each marker to its link's origin."
        )
    if cal.history:
        cost_ax, sigma_ax = sheet.axes_row(0.26, 2)
        plot_cost(cal, cost_ax)
        plot_sigma(cal, sigma_ax)
        sheet.caption(
            "Left: the cost (negative log-likelihood, eq. 2.5) after each outer iteration, shifted so that its "
            "minimum is 1 (log scale); it need not fall monotonically, because re-estimating σ changes the "
            "likelihood itself. Right: the noise level σ of each sensor type, re-estimated every iteration "
            f"(dynamic variance adjustment, §2.3.5): {sigma_words(cal)}."
        )
    save_page(pdf, sheet.fig)

    if ev.residuals:
        sheet = Sheet(f"{title}: residuals")
        panels = list(ev.residuals.items())
        if ev.heldout_errors is not None:
            panels.append(("held-out markers", (ev.heldout_errors, "m (distance)")))
        height = min(0.25, (sheet.room() - 0.1) / len(panels) - 0.025 - 0.012)  # room for titles and caption
        for g, (r, unit) in panels:
            ax = sheet.axes(height)
            plot_residual_hist(r, g, unit, ax)
            ax.set_ylabel("samples")
        sheet.caption(residual_caption(ev))
        save_page(pdf, sheet.fig)


def residual_caption(ev: Evaluation) -> str:
    """What the residual histograms show: the fit log's, and the held-out markers' when drawn."""
    units = ", ".join(f"{g} in {u}" for g, (_, u) in ev.residuals.items() if g != "markers")
    text = (
        f"Residuals at the fitted joint angles (the fit log): pots, reading minus model ({units}); markers, "
        "distance between measured and modelled position, m (occluded samples left out)."
    )
    if ev.heldout_errors is not None:
        text += (
            f" 'held-out markers': distance between the markers measured on {Path(ev.heldout[0][0]).name} and "
            "those predicted from its pots alone."
        )
    return text
