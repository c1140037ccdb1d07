"""Report section for calib.yaml (thesis ch. 2 figures; registers itself on import).

Pages: parameter table; marker positions before/after on the robot skeleton (Figs. 2.8-2.9);
convergence of the cost (``fit.history``); residual histograms per sensor type (reloads the
log named in the header and the tracked joint angles ``<stem>.q.h5`` when they exist); what the
data could not determine (``unobservable`` pots, ``gauges``) in words on the first page; and the
cross-sensor MAE table (Tables 2.1-2.2) of files where an older ``diegocal predict`` recorded one.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from diegocal.errors import DiegocalError
from diegocal.io import load_log, load_yaml
from diegocal.report.registry import ReportContext, Section, is_bundle, register_section
from diegocal.report.style import COLORS, axes_or_new
from diegocal.stac.calibration import Calibration


def recognise(path: Path) -> bool:
    return is_bundle(path, "calibration")


def describe(path: Path) -> dict:
    """Title-page facts from the bundle header ({log, robot, command, created}; legacy ``meta``)."""
    from diegocal.io.bundle import load_bundle

    bundle = load_bundle(path)
    data = bundle.data
    meta = data.get("meta") or {}
    out = {k: data.get(k, meta.get(k)) for k in ("log", "command", "created")}
    rec = bundle.robot
    out["robot"] = rec["dir"] or rec["name"]
    return {k: v for k, v in out.items() if v}


# ----------------------------------------------------------------------------- plots
def plot_cost(cal: Calibration, ax=None):
    """Cost (negative log-likelihood, eq. 2.5) per outer iteration."""
    ax = axes_or_new(ax)
    it = [h["iteration"] for h in cal.history]
    cost = np.array([h["cost"] for h in cal.history], float)
    ax.plot(it, cost - np.nanmin(cost) + 1.0, "o-", color=COLORS["model"], ms=3)
    ax.set_yscale("log")
    ax.set_xlabel("iteration")
    ax.set_ylabel("cost − min + 1")
    ax.set_title(f"Convergence ({cal.method}, {cal.fit.iterations} iterations, {cal.fit.seconds:.1f} s)")
    return ax


def plot_sigma(cal: Calibration, ax=None):
    """Noise levels per sensor type over the iterations (dynamic variance adjustment, §2.3.5)."""
    ax = axes_or_new(ax)
    it = [h["iteration"] for h in cal.history]
    for key, label in (("sigma_pots", "pots (V)"), ("sigma_markers", "markers (m)")):
        ax.semilogy(it, [h.get(key) or np.nan for h in cal.history], label=label)
    ax.set_xlabel("iteration")
    ax.set_ylabel("noise σ [V for pots, m for markers]")
    ax.legend()
    ax.set_title("Dynamic variance adjustment (§2.3.5)")
    return ax


def plot_markers_on_robot(skeleton: dict, ax=None, axes=(0, 2)):
    """Figs. 2.8-2.9: robot skeleton at neutral with nominal (seed) vs fitted marker positions.

    skeleton : {"links": (L, 3) link origins, "parents": (L,) index or -1, "nominal": (M, 3),
    "fitted": (M, 3)} all in the base frame, m; ``axes`` picks the projection plane.
    """
    ax = axes_or_new(ax)
    a, b = axes
    pos, par = skeleton["links"], skeleton["parents"]
    for i, p in enumerate(par):
        if p >= 0:
            ax.plot([pos[p, a], pos[i, a]], [pos[p, b], pos[i, b]], color="0.6", lw=1.5)
    ax.plot(pos[:, a], pos[:, b], ".", color="0.4", ms=4)
    nom, fit = skeleton["nominal"], skeleton["fitted"]
    ax.plot(
        nom[:, a],
        nom[:, b],
        "o",
        mfc="none",
        color=COLORS["baseline"],
        label="seed (link origins / nominal)",
    )
    ax.plot(fit[:, a], fit[:, b], "o", color=COLORS["model"], ms=4, label="calibrated")
    for n0, n1 in zip(nom, fit, strict=True):
        ax.plot([n0[a], n1[a]], [n0[b], n1[b]], color=COLORS["model"], lw=0.5)
    ax.set_aspect("equal")
    ax.set_xlabel("xyz"[a] + " [m]")
    ax.set_ylabel("xyz"[b] + " [m]")
    ax.legend(loc="best")
    return ax


def plot_residual_hist(residuals: np.ndarray, label: str, unit: str, ax=None):
    """Histogram of one sensor type's residuals."""
    ax = axes_or_new(ax)
    r = residuals[np.isfinite(residuals)]
    ax.hist(r, bins=60, color=COLORS["residual"], alpha=0.8)
    ax.set_title(f"{label}: RMS {np.sqrt(np.mean(r * r)):.3g} {unit}, n = {r.size}")
    ax.set_xlabel(f"residual [{unit}]")
    return ax


# ----------------------------------------------------------------------------- data
def skeleton(cal: Calibration, robot) -> dict:
    """Link origins at the neutral pose and nominal/fitted markers in the base frame."""
    from diegocal.robot.batch import BatchKinematics

    kin = BatchKinematics(robot)
    poses = kin.joint_poses(robot.neutral()[None])
    parents = kin.parent.copy()
    links = np.concatenate([np.zeros((1, 3)), poses.p[0]])  # root + joint origins
    names = [m.link for m in robot.sensors.markers]
    Rl, pl = kin.link_poses(poses, names)
    nominal = np.array([m.xyz for m in robot.sensors.markers], float).reshape(-1, 3)
    index = {n: i for i, n in enumerate(cal.marker_names)}
    fitted = np.array([cal.marker_xyz[index[m.name]] if m.name in index else m.xyz for m in robot.sensors.markers])
    to_base = lambda d: np.einsum("mij,mj->mi", Rl[0], d) + pl[0]  # noqa: E731
    return {
        "links": links,
        "parents": np.concatenate([[-1], parents + 1]),
        "nominal": to_base(np.zeros_like(nominal)),
        "fitted": to_base(fitted),
    }


def residuals_by_type(cal: Calibration, robot, log, q) -> dict:
    """{type: (residuals, unit)} of the log under the calibration at the tracked q."""
    from diegocal.stac.model import MARKERS, Observation

    obs = Observation(log, robot)
    params = obs.params_from(cal)
    st = obs.state(q)
    out = {}
    rp = params.gain * st.s + params.bias - obs.pots
    for g in obs.groups:
        if g == MARKERS:
            xb = np.einsum("tmij,mj->tmi", st.Rl, params.xyz) + st.pl
            d = np.linalg.norm(xb @ params.R.T + params.T - obs.markers, axis=-1)
            out[g] = (d[obs.valid], "m (distance)")
        else:
            out[g] = (rp[:, obs.kinds == g].ravel(), "V")
    return out


def coverage_lines(cal: Calibration) -> list[str]:
    """What the data could not determine (calib.yaml's ``unobservable`` and ``gauges``), in words."""
    lines = []
    if cal.unobservable:
        lines.append(f"Unobservable: {len(cal.unobservable)} pot(s) keep their nominal gain and bias")
        lines += [f"  {u['pot']}: {u['reason']}" for u in cal.unobservable]
    if cal.gauges:
        lines.append(f"Gauges: {len(cal.gauges)} joint zero(s) the markers cannot fix")
        lines += [f"  {g['joint']}: {g['reason']}" for g in cal.gauges]
    return lines + [""] if lines else []


def param_lines(cal: Calibration) -> list[str]:
    lines = [
        f"method: {cal.method}   iterations: {cal.fit.iterations}   converged: {cal.fit.converged}",
        "σ by type: " + ", ".join(f"{k} {v:.3g}" for k, v in cal.sigma_by_group.items()),
        "",
        *coverage_lines(cal),
        f"{'pot':<20}{'gain':>10}{'± se':>10}{'bias':>10}{'± se':>10}",
    ]
    gse = cal.gain_se if cal.gain_se is not None else np.full(len(cal.gain), np.nan)
    bse = cal.bias_se if cal.bias_se is not None else np.full(len(cal.gain), np.nan)
    nominal = {u["pot"] for u in cal.unobservable}
    gauge = {g["pot"] for g in cal.gauges}
    for i, n in enumerate(cal.pot_names):
        note = "  nominal (unobservable)" if n in nominal else "  bias nominal (gauge)" if n in gauge else ""
        lines.append(f"{n:<20}{cal.gain[i]:>10.4f}{gse[i]:>10.2g}{cal.bias[i]:>10.4f}{bse[i]:>10.2g}{note}")
    return lines


def cross_sensor_lines(rows) -> list[str]:
    """Tables 2.1-2.2: MAE of each target type given each source set."""
    targets = sorted({t for r in rows for t in r.get("mae", {})})
    lines = [f"{'sensor set':<32}" + "".join(f"{t:>12}" for t in targets)]
    for r in rows:
        src = set(r.get("from", []))
        cells = []
        for t in targets:
            v = r["mae"].get(t)
            cells.append(f"{'-' if v is None else (f'({v:.4f})' if t in src else f'{v:.4f}'):>12}")
        lines.append(f"{'+'.join(r.get('from', [])):<32}" + "".join(cells))
    return lines + [
        "",
        "MAE: markers in m (mean distance), pots in sensor units; (…) = same type as a source.",
    ]


# ----------------------------------------------------------------------------- pages
def pages(path: Path, pdf, context: ReportContext) -> None:
    """The section's pages, assembled in :mod:`diegocal.report.stac_pages`."""
    from diegocal.report.stac_pages import pages as document_pages

    document_pages(Path(path), pdf, context)


def _load_context(raw: dict, path: Path, context: ReportContext):
    """Robot, log and tracked q (``stac --joint-angles``) named in the bundle when they still exist
    (else None)."""
    from diegocal.io import q_log_path
    from diegocal.io.bundle import load_bundle
    from diegocal.robot import load_robot

    robot = log = q = None
    try:
        bundle = load_bundle(path)
        rdir = context.robot or bundle.robot["dir"]
        robot = load_robot(rdir) if rdir is not None and Path(rdir).exists() else None
        if bundle.log and Path(bundle.log).exists():
            log = load_log(bundle.log).without_truth()
        qp = Path((raw.get("meta") or {}).get("joint_angles") or q_log_path(Path(path)))  # legacy: beside it
        if qp.exists() and log is not None:
            qlog = load_log(qp)
            q = qlog.streams["q"].data if qlog.n_samples == log.n_samples else None
    except (DiegocalError, OSError, KeyError):
        pass
    return robot, log, q


def _abstract(path: Path, context: ReportContext) -> list[str]:
    from diegocal.report.stac_pages import abstract

    return abstract(Path(path), context)


def _headline(path: Path, context: ReportContext) -> str:
    from diegocal.report.stac_pages import headline

    return headline(Path(path), context)


register_section(
    Section(
        "stac",
        recognise,
        pages,
        describe,
        heading="Kinematic calibration (STAC)",
        abstract=_abstract,
        headline=_headline,
    )
)
