"""Report section for sgp/ model directories (thesis ch. 3 figures; registers itself on import).

Recognises a directory holding ``sgp.yaml`` (one model), or a directory whose sub-directories
are models (a comparison of methods, e.g. ``results/{pr,gp,prgp,sgp}.sgp``), and the log that
``diegocal predict`` writes for such a model (held-out nMSE and ±2σ coverage per joint); other
logs are left to the log section. The words and tables are in :mod:`.sgp_text`.

Pages of a model: its opening in plain words, the per-joint table (nMSE in-sample and held-out,
±2σ coverage, the guard's choice, noise levels), the model's facts, the GP length-scales and the
identified parameters; then measured vs predicted torques with ±2σ bands on the training log and
on the held-out log; then thesis Fig. 3.10-style prediction ±2σ along each joint angle beside the
latent std over a (q_j, qd_j) slice. A comparison opens with one table over every model and joint.
Figures flow: as many panels per page as fit, each page's panels captioned below them.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from diegocal.report import sgp_text
from diegocal.report.layout import GAP, Column, Sheet, table_sheets
from diegocal.report.registry import Section, register_section
from diegocal.report.sgp_text import model_dirs
from diegocal.report.style import COLORS, axes_or_new, save_page

HEADING = "Torque model (SGP)"
PREDICTION_HEADING = "Held-out torque prediction"
MAX_SAMPLES = 1500  # a time series longer than this shows its first MAX_SAMPLES samples
SLICE_POINTS = 150
BAND_HEIGHT = 0.19  # one joint's time series, fraction of the page
ROW_HEIGHT = 0.22  # one joint's slice and uncertainty map
SHRINK = 0.75  # panels may shrink to this share of their height to fill a page

__all__ = ["model_dirs", "recognise", "is_prediction", "heldout_score", "plot_band", "plot_prediction_band"]


def recognise(path: Path) -> bool:
    return bool(model_dirs(path))


def describe(path: Path) -> dict:
    from diegocal.sgp import load_summary

    dirs = model_dirs(path)
    if len(dirs) == 1:
        return dict(load_summary(dirs[0]).get("meta") or {})
    logs = {str((load_summary(d).get("meta") or {}).get("log") or "") for d in dirs} - {""}
    return {"models": ", ".join(p.name for p in dirs), "log": logs.pop() if len(logs) == 1 else None}


def prismatic_joints(robot) -> frozenset:
    """Names of the robot's prismatic joints (their torque is a force, N)."""
    out = set()
    for name in robot.joint_names:
        kind = robot.model.joints[robot.model.getJointId(name)].shortname().replace("JointModel", "")
        if kind in ("PX", "PY", "PZ", "PrismaticUnaligned"):
            out.add(name)
    return frozenset(out)


def _unit(model, joint: str) -> str:
    return "N" if joint in prismatic_joints(model.robot) else "N·m"


# ----------------------------------------------------------------------------- plots
def plot_band(x, measured, mean, std, ax=None, parametric=None, label: str = "model"):
    """Measured vs predicted torque of one joint with the ±2σ band of a measured torque (eq. 3.20);
    ``parametric``: the parametric part alone, dashed. Arrays (T,): x (s or sample), torques N·m."""
    ax = axes_or_new(ax)
    x, measured, mean, std, parametric = gaps_broken(x, measured, mean, std, parametric)
    ax.fill_between(x, mean - 2 * std, mean + 2 * std, color=COLORS["band"], alpha=0.25, lw=0, label="±2σ")
    ax.plot(x, mean, color=COLORS["model"], lw=1.4, label=label)  # wide, below: the measured line shows on it
    ax.plot(x, measured, color=COLORS["measured"], lw=0.5, label="measured")
    if parametric is not None:
        ax.plot(x, parametric, color=COLORS["baseline"], lw=0.6, ls="--", label="parametric")
    headroom(ax)
    ax.legend(ncol=4, fontsize=6, loc="upper right", handlelength=1.5, columnspacing=1.0)
    return ax


def gaps_broken(x, *ys):
    """``x`` (T,) and the series ``ys`` (T,) with NaN put into every gap of ``x`` wider than three
    median steps (a diagnosis's training blocks are not contiguous): no line is drawn across a gap."""
    x = np.asarray(x, float)
    steps = np.diff(x)
    if len(steps) < 2:
        return (x, *ys)
    at = np.flatnonzero(steps > 3 * np.median(steps)) + 1
    return (np.insert(x, at, np.nan), *(None if y is None else np.insert(np.asarray(y, float), at, np.nan) for y in ys))


def headroom(ax, share: float = 0.25) -> None:
    """Raise the top of the y axis by ``share`` of its range: the legend then covers no data."""
    lo, hi = ax.get_ylim()
    ax.set_ylim(lo, hi + share * (hi - lo))


def _window(n: int) -> tuple[slice, str]:
    """The samples a time series shows, and the words for the axis."""
    if n <= MAX_SAMPLES:
        return slice(0, n), f"{n} samples"
    return slice(0, MAX_SAMPLES), f"first {MAX_SAMPLES} of {n} samples"


def training_prediction(model):
    """The model's prediction of its first MAX_SAMPLES training samples (TorquePrediction)."""
    n = model.robot.n_joints
    U = model.U_[_window(len(model.U_))[0]]
    time = None if model.time_ is None else model.time_[: len(U)]
    return model.predict_arrays(U[:, :n], U[:, n : 2 * n], U[:, 2 * n :], time)


def plot_torque_band(model, k: int, ax=None, pred=None):
    """Training log: measured vs predicted torque of fitted joint ``k`` with ±2σ (eq. 3.20)."""
    ax = axes_or_new(ax)
    pred = training_prediction(model) if pred is None else pred
    window, words = _window(len(model.U_))
    m = len(pred.tau)
    has_time = model.time_ is not None
    x = model.time_[:m] if has_time else np.arange(m)
    kind = model.options.kind
    par = pred.tau_parametric[:, k] if kind in ("sgp", "prgp") else None
    plot_band(x, model.tau_[window, k], pred.tau[:, k], pred.tau_std[:, k], ax, par, label="mean")
    name = model.joint_names[k]
    ax.set_title(f"{name}: training log (nMSE {float(model.nmse_in_sample_[k]):.3g})")
    ax.set_xlabel(f"time [s]  ({words})" if has_time else f"training sample  ({words})")
    ax.set_ylabel(f"τ {name} [{_unit(model, name)}]")
    return ax


def plot_heldout_band(model, held, k: int, ax=None):
    """Held-out log (:class:`~diegocal.report.sgp_text.HeldOut`): measured vs predicted with ±2σ."""
    ax = axes_or_new(ax)
    window, words = _window(len(held.time))
    name = model.joint_names[k]
    par = held.parametric[window, k] if model.options.kind in ("sgp", "prgp") else None
    plot_band(
        held.time[window],
        held.measured[window, k],
        held.predicted[window, k],
        held.std[window, k],
        ax,
        par,
        label="mean",
    )
    e, _, c = held.of(name)
    ax.set_title(f"{name}: held-out log (nMSE {e:.3g}, {100 * c:.0f} % in ±2σ)")
    ax.set_xlabel(f"time [s]  ({words})")
    ax.set_ylabel(f"τ {name} [{_unit(model, name)}]")
    return ax


def _slice_states(model, r: int, grid: np.ndarray, velocity: np.ndarray | None = None):
    """States along robot joint ``r``'s angle (and velocity), the other inputs at their training mean."""
    n = model.robot.n_joints
    U = np.repeat(model.U_.mean(0)[None], len(grid), axis=0)
    U[:, r] = grid
    if velocity is not None:
        U[:, n + r] = velocity
    return U[:, :n], U[:, n : 2 * n], U[:, 2 * n :]


def plot_angle_slice(model, k: int, ax=None):
    """Thesis Fig. 3.10: prediction ±2σ (latent) along q_j, the other inputs at their training mean."""
    ax = axes_or_new(ax)
    r = model.rows[k]
    lo, hi = max(model.robot.lower[r], -np.pi), min(model.robot.upper[r], np.pi)
    grid = np.linspace(lo, hi, SLICE_POINTS)
    pred = model.predict_arrays(*_slice_states(model, r, grid))
    mu, sd = pred.tau[:, k], pred.tau_std_latent[:, k]
    name = model.joint_names[k]
    ax.fill_between(grid, mu - 2 * sd, mu + 2 * sd, color=COLORS["band"], alpha=0.25, lw=0, label="±2σ (latent)")
    ax.plot(grid, mu, color=COLORS["model"], label=f"{model.options.kind} mean")
    seen = model.U_[:, r]
    ax.plot(
        seen,
        np.full(len(seen), 0.03),
        "|",
        color=COLORS["measured"],
        ms=5,
        alpha=0.3,
        transform=ax.get_xaxis_transform(),
        label=f"training q ({len(seen)})",
    )
    ax.ticklabel_format(axis="y", useOffset=False)
    headroom(ax, 0.45)
    ax.set_xlabel(f"q.{name} [rad]")
    ax.set_ylabel(f"τ {name} [{_unit(model, name)}]")
    ax.set_title(f"{name}: along its angle (Fig. 3.10)")
    ax.legend(fontsize=6, loc="upper right")
    return ax


def plot_uncertainty_map(model, k: int, ax=None, size: int = 40):
    """Latent predictive std over (q_j, qd_j), other inputs at their training mean (§3.5.1)."""
    ax = axes_or_new(ax)
    r, n = model.rows[k], model.robot.n_joints
    name = model.joint_names[k]
    q_seen, qd_seen = model.U_[:, r], model.U_[:, n + r]
    pad_q, pad_v = 0.5 * np.ptp(q_seen) + 1e-3, 0.5 * np.ptp(qd_seen) + 1e-3
    qs = np.linspace(q_seen.min() - pad_q, q_seen.max() + pad_q, size)
    vs = np.linspace(qd_seen.min() - pad_v, qd_seen.max() + pad_v, size)
    Q, V = np.meshgrid(qs, vs)
    pred = model.predict_arrays(*_slice_states(model, r, Q.ravel(), V.ravel()))
    S = pred.tau_std_latent[:, k].reshape(Q.shape)
    mesh = ax.pcolormesh(Q, V, S, shading="auto", cmap="viridis", rasterized=True)  # no seams in the PDF
    ax.grid(False)
    ax.figure.colorbar(mesh, ax=ax, label=f"latent std [{_unit(model, name)}]")
    ax.plot(q_seen, qd_seen, ".", color="w", ms=1, alpha=0.5, label=f"training samples ({len(q_seen)})")
    ax.set_xlabel(f"q.{name} [rad]")
    ax.set_ylabel(f"qd.{name} [rad/s]")
    ax.set_title(f"{name}: uncertainty over (q, qd)")
    ax.legend(fontsize=6, loc="upper right", markerscale=4, facecolor="0.45", labelcolor="w")
    return ax


def plot_nmse_comparison(models: list[Path], context, ax=None):
    """Grouped bars: nMSE per joint (groups) and model (colours), in-sample (hatched) and held-out
    (solid) when a held-out log was given; log scale."""
    from diegocal.sgp import load_summary

    ax = axes_or_new(ax)
    summaries = {m.name: load_summary(m) for m in models}
    helds = {m.name: sgp_text.heldout(m, context) for m in models}
    joints = list(next(iter(summaries.values()))["nmse_in_sample"])
    kinds = ["in-sample"] + (["held-out"] if all(h is not None for h in helds.values()) else [])
    width = 0.8 / (len(summaries) * len(kinds))
    x = np.arange(len(joints))
    i = 0
    for c, (name, s) in enumerate(summaries.items()):
        color = f"C{c}"
        for kind in kinds:
            if kind == "in-sample":
                vals = [s["nmse_in_sample"].get(j, np.nan) for j in joints]
            else:
                vals = [(helds[name].of(j) or (np.nan,))[0] for j in joints]
            hatch = "///" if kind == "in-sample" and len(kinds) > 1 else None
            fill = "none" if hatch else color
            ax.bar(
                x + i * width - 0.4 + width / 2,
                vals,
                width,
                color=fill,
                edgecolor=color,
                hatch=hatch,
                label=f"{name}, {kind}",
            )
            i += 1
    ax.set_xticks(x, joints)
    ax.set_yscale("log")
    ax.set_ylabel("nMSE (log scale)")
    ax.set_title("nMSE per joint and model")
    ax.legend(fontsize=6, ncol=len(kinds))
    return ax


# ----------------------------------------------------------------------------- flowing pages
def flow(
    sheets: list[Sheet], title: str, heading: str, caption: str, n: int, height: float, draw, last: bool = False
) -> None:
    """``n`` panels (``draw(k, sheet, height)`` places panel k), as many per sheet as fit, under
    ``heading``, the caption below each sheet's panels; new sheets are titled ``title (continued)``.
    Panels are ``height`` high, or down to ``SHRINK`` of it when that fits one more on the sheet.
    ``last``: nothing follows in the section, so no sheet is left holding a lone panel."""
    k = 0
    while k < n:
        sheet = sheets[-1]
        room = sheet.room() - 0.035 - sheet.paragraph_height(caption, size=8)
        extra = 0.025 + GAP  # title room and gap of each panel
        fit = int(room // (height + extra))
        tight = int(room // (SHRINK * height + extra))
        h = height
        if tight > fit and fit < n - k:  # smaller panels take one more (or the rest)
            fit = min(tight, n - k)
            h = min(height, room / fit - extra)
        if fit < 1:
            sheets.append(Sheet(f"{title} (continued)"))
            continue
        take = min(fit, n - k)
        lone = last and n - k - take == 1 and take >= 2  # the next sheet would hold a lone panel
        take -= lone
        sheet.heading(heading + (" (continued)" if k else ""))
        for i in range(k, k + take):
            draw(i, sheet, h)
        sheet.caption(caption)
        k += take
        if lone:  # the two last panels share the next sheet
            sheets.append(Sheet(f"{title} (continued)"))


def more(sheets: list[Sheet], title: str, columns, rows, notes, room: float = 0.2) -> None:
    """A table below the last sheet's content when ``room`` is left there, else from a new page; a
    long table fills its pages (figures follow it)."""
    if sheets[-1].room() > room:
        sheets[-1:] = table_sheets(title, columns, rows, notes=notes, sheet=sheets[-1], balance=False)
    else:
        sheets += table_sheets(title, columns, rows, notes=notes, balance=False)


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


SLICE_CAPTION = (
    "Left: the predicted torque along the joint's own angle, every other input held at its training mean (thesis "
    "Fig. 3.10); blue band: ±2 latent std, the model's uncertainty about the noise-free torque; grey ticks at the "
    "bottom: the angles seen in training. Right: the latent std over the joint's angle and velocity, the other "
    "inputs at their training mean; white dots: the training samples. The uncertainty should grow away from the "
    "data (thesis §3.5.1)."
)


def model_pages(path: Path, sheets: list[Sheet], context, title: str, comparison: bool, last: bool = True) -> None:
    """One model's tables and figures, continuing on ``sheets`` (``last``: the section's last model)."""
    from diegocal.sgp import load_model, load_summary

    summary, model = load_summary(path), load_model(path)
    if comparison:
        if sheets[-1].room() < 0.3:
            sheets.append(Sheet(f"{title} (continued)"))
        sheets[-1].heading(f"Model {path.name}", size=12.5)
    for p in sgp_text.model_paragraphs(path, context):
        if not sheets[-1].paragraph(p):
            sheets.append(Sheet(f"{title} (continued)"))
            sheets[-1].paragraph(p)
    if not comparison:
        more(sheets, "Per joint", *sgp_text.joint_table([path], context))
    facts = [Column("quantity", align="left"), Column("value", align="left"), Column("unit", align="left")]
    more(sheets, f"How {path.name} was fitted", facts, sgp_text.facts_rows(summary, model), ())
    scales = sgp_text.lengthscale_table(summary)
    if scales is not None:
        more(sheets, "GP length-scales", *scales)
    guard = sgp_text.guard_table(summary)
    if guard is not None:
        more(sheets, "The guard's cross-validation", *guard)
    params = sgp_text.parameter_table(summary, prismatic_joints(model.robot))
    if params[1]:
        more(sheets, "Identified parameters", *params)
    kind, n = model.options.kind, len(model.joint_names)
    pred = training_prediction(model)
    held = sgp_text.heldout(path, context)

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

    def row(k, sheet, h):
        left, right = sheet.axes_row(h, 2, gap=0.12)
        plot_angle_slice(model, k, left)
        plot_uncertainty_map(model, k, right)

    flow(
        sheets, title, f"{path.name}: uncertainty in state space (§3.5.1)", SLICE_CAPTION, n, ROW_HEIGHT, row, last=last
    )


def pages(path: Path, pdf, context) -> None:
    dirs = model_dirs(path)
    title = f"{HEADING}: {Path(path).name}"
    sheets = [Sheet(title)]
    comparison = len(dirs) > 1
    if comparison:
        sheets[-1].paragraph(sgp_text.comparison_paragraph(dirs, context))
        more(sheets, "Comparison per model and joint", *sgp_text.joint_table(dirs, context))
        flow(
            sheets,
            title,
            "nMSE per joint and model",
            "nMSE (squared error over the measured torque's variance; log scale, lower is better) of each model "
            "on each joint: hatched, on the training log; solid, on the held-out log when one was given.",
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
    from diegocal.io import load_log
    from diegocal.report.logs import LOG_SUFFIXES

    path = Path(path)
    if path.suffix.lower() not in LOG_SUFFIXES or not path.is_file():
        return False
    try:
        return all(load_log(path).has(s) for s in ("tau", "tau_std", "tau_measured"))
    except Exception:  # noqa: BLE001 - not a readable log: not ours
        return False


def heldout_score(log):
    """:class:`diegocal.evaluate.Score` of a prediction log: nMSE, RMSE, ±2σ coverage per joint."""
    from diegocal.evaluate import score

    pred = log.stream("tau")
    measured = log.stream("tau_measured").select(pred.names).data
    std = log.stream("tau_std").select(pred.names).data
    return score(measured, pred.data, pred.names, std=std, unit="N·m")


def plot_prediction_band(log, k: int, ax=None, sc=None):
    """A prediction log: measured vs predicted torque of joint ``k`` with the ±2σ band (eq. 3.20)."""
    ax = axes_or_new(ax)
    pred = log.stream("tau")
    name = pred.names[k]
    window, words = _window(log.n_samples)
    sd = log.stream("tau_std").select([name]).data[window, 0]
    measured = log.stream("tau_measured").select([name]).data[window, 0]
    plot_band(log.time[window], measured, pred.data[window, k], sd, ax, label="predicted mean")
    sc = heldout_score(log) if sc is None else sc
    ax.set_title(f"{name}: nMSE {sc.nmse[k]:.3g}, {100 * sc.coverage[k]:.0f} % inside ±2σ")
    ax.set_xlabel(f"time [s]  ({words})")
    ax.set_ylabel(f"τ {name} [N·m]")
    return ax


def _prediction(path: Path):
    from diegocal.io import load_log

    log = load_log(path)
    return log, heldout_score(log)


def describe_prediction(path: Path) -> dict:
    """Title-page facts of a prediction log: what made it (Log.source; {} for a file made before
    predict recorded it)."""
    from diegocal.io import load_log

    return dict(load_log(path).source or {})


def prediction_abstract(path: Path, context=None) -> list[str]:
    return sgp_text.prediction_paragraphs(path, *_prediction(path))


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
    columns, rows = sgp_text.prediction_table(sc)
    sheets = table_sheets(
        title, columns, rows, intro=sgp_text.prediction_paragraphs(path, log, sc), notes=(sgp_text.PREDICTION_NOTE,)
    )
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
        abstract=sgp_text.abstract,
        headline=sgp_text.headline,
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
