"""Report section for sgp/ model directories (thesis ch. 3 figures; registers itself on import).

Recognises a directory holding ``sgp.yaml`` (one model), or a directory whose sub-directories
are models (a comparison of methods, e.g. ``results/{pr,gp,prgp,sgp}.sgp``), and the log that
``diegocal predict`` writes for such a model (held-out nMSE and ±2σ coverage per joint); other
logs are left to the log section. Pages: summary; measured vs predicted torques with ±2σ bands on the training
set; thesis Fig. 3.10-style prediction ±2σ along each joint angle with the other inputs held at
their training mean; the latent std over a (q_j, qd_j) slice with the training samples; and, for
a comparison, nMSE per joint and method.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from diegocal.report.registry import Section, register_section
from diegocal.report.style import COLORS, axes_or_new, page, save_page, text_page
from diegocal.sgp import is_model_dir, load_model, load_summary

MAX_JOINTS_PER_PAGE = 4
SLICE_POINTS = 150


def model_dirs(path: Path) -> list[Path]:
    """The model directories a path stands for: itself, or its model sub-directories."""
    path = Path(path)
    if is_model_dir(path):
        return [path]
    if path.is_dir():
        return sorted(p for p in path.iterdir() if is_model_dir(p))
    return []


def recognise(path: Path) -> bool:
    return bool(model_dirs(path))


def describe(path: Path) -> dict:
    dirs = model_dirs(path)
    if len(dirs) == 1:
        return dict(load_summary(dirs[0]).get("meta") or {})
    return {"models": ", ".join(p.name for p in dirs)}


# ----------------------------------------------------------------------------- plots
def plot_torque_band(model, joint: int, ax=None, max_samples: int = 1500):
    """Measured vs predicted torque of one joint on the training samples, with ±2σ (eq. 3.20)."""
    ax = axes_or_new(ax)
    n = model.robot.n_joints
    U = model.U_[:max_samples]
    pred = model.predict_arrays(U[:, :n], U[:, n : 2 * n], U[:, 2 * n :])
    k = np.arange(len(U))
    mu, sd = pred.tau[:, joint], pred.tau_std[:, joint]
    ax.fill_between(k, mu - 2 * sd, mu + 2 * sd, color=COLORS["band"], alpha=0.25, lw=0, label="±2σ")
    ax.plot(k, model.tau_[: len(U), joint], color=COLORS["measured"], lw=0.6, label="measured")
    ax.plot(k, mu, color=COLORS["model"], lw=0.8, label=model.options.kind)
    if model.options.kind in ("sgp", "prgp"):
        ax.plot(
            k,
            pred.tau_parametric[:, joint],
            color=COLORS["baseline"],
            lw=0.6,
            ls="--",
            label="parametric part",
        )
    name = model.joint_names[joint]
    err = float(model.nmse_in_sample_[joint])
    ax.set_title(f"{name}: training fit (nMSE {err:.3g})")
    ax.set_xlabel("sample")
    ax.set_ylabel("τ [N·m]")
    ax.legend(ncol=4, fontsize=6)
    return ax


def _slice_states(model, joint: int, grid: np.ndarray, velocity: np.ndarray | None = None):
    n = model.robot.n_joints
    base = model.U_.mean(0)
    U = np.repeat(base[None], len(grid), axis=0)
    U[:, joint] = grid
    if velocity is not None:
        U[:, n + joint] = velocity
    return U[:, :n], U[:, n : 2 * n], U[:, 2 * n :]


def plot_angle_slice(model, joint: int, ax=None):
    """Thesis Fig. 3.10: prediction ±2σ along q_j, the other inputs at their training mean."""
    ax = axes_or_new(ax)
    lo, hi = model.robot.lower[joint], model.robot.upper[joint]
    lo, hi = max(lo, -np.pi), min(hi, np.pi)
    grid = np.linspace(lo, hi, SLICE_POINTS)
    pred = model.predict_arrays(*_slice_states(model, joint, grid))
    mu, sd = pred.tau[:, joint], pred.tau_std_latent[:, joint]
    ax.fill_between(grid, mu - 2 * sd, mu + 2 * sd, color=COLORS["band"], alpha=0.25, lw=0, label="±2σ (latent)")
    ax.plot(grid, mu, color=COLORS["model"], label=model.options.kind)
    seen = model.U_[:, joint]
    ax.plot(
        seen,
        np.full_like(seen, ax.get_ylim()[0]),
        "|",
        color=COLORS["measured"],
        ms=6,
        alpha=0.3,
        label="training q",
    )
    ax.set_xlabel(f"q.{model.joint_names[joint]} [rad]")
    ax.set_ylabel("τ [N·m]")
    ax.set_title(f"{model.joint_names[joint]}: prediction along its angle (Fig. 3.10)")
    ax.legend(fontsize=6)
    return ax


def plot_uncertainty_map(model, joint: int, ax=None, size: int = 40):
    """Latent predictive std over (q_j, qd_j), other inputs at their training mean (§3.5.1)."""
    ax = axes_or_new(ax)
    n = model.robot.n_joints
    q_seen, qd_seen = model.U_[:, joint], model.U_[:, n + joint]
    pad_q, pad_v = 0.5 * np.ptp(q_seen) + 1e-3, 0.5 * np.ptp(qd_seen) + 1e-3
    qs = np.linspace(q_seen.min() - pad_q, q_seen.max() + pad_q, size)
    vs = np.linspace(qd_seen.min() - pad_v, qd_seen.max() + pad_v, size)
    Q, V = np.meshgrid(qs, vs)
    pred = model.predict_arrays(*_slice_states(model, joint, Q.ravel(), V.ravel()))
    S = pred.tau_std_latent[:, joint].reshape(Q.shape)
    mesh = ax.pcolormesh(Q, V, S, shading="auto", cmap="viridis")
    ax.figure.colorbar(mesh, ax=ax, label="latent std [N·m]")
    ax.plot(q_seen, qd_seen, ".", color="w", ms=1, alpha=0.5)
    ax.set_xlabel(f"q.{model.joint_names[joint]} [rad]")
    ax.set_ylabel(f"qd.{model.joint_names[joint]} [rad/s]")
    ax.set_title(f"{model.joint_names[joint]}: uncertainty over a state slice")
    return ax


def plot_nmse_comparison(summaries: dict, ax=None):
    """Grouped bars: in-sample nMSE per joint (groups) and method (bars); log scale."""
    ax = axes_or_new(ax)
    names = list(summaries)
    joints = list(next(iter(summaries.values()))["nmse_in_sample"])
    width = 0.8 / max(len(names), 1)
    x = np.arange(len(joints))
    for i, name in enumerate(names):
        vals = [summaries[name]["nmse_in_sample"].get(j, np.nan) for j in joints]
        ax.bar(x + i * width - 0.4 + width / 2, vals, width, label=name)
    ax.set_xticks(x, joints)
    ax.set_yscale("log")
    ax.set_ylabel("nMSE (in-sample)")
    ax.set_title("nMSE per joint and method")
    ax.legend(fontsize=6)
    return ax


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
    return score(measured, pred.data, pred.names, std=std)


def plot_prediction_band(log, joint: int, ax=None, max_samples: int = 1500):
    """Held-out: measured vs predicted torque of one joint with the ±2σ band (eq. 3.20)."""
    ax = axes_or_new(ax)
    pred = log.stream("tau")
    name = pred.names[joint]
    t = log.time[:max_samples]
    mu = pred.data[:max_samples, joint]
    sd = log.stream("tau_std").select([name]).data[:max_samples, 0]
    ax.fill_between(t, mu - 2 * sd, mu + 2 * sd, color=COLORS["band"], alpha=0.25, lw=0, label="±2σ")
    ax.plot(
        t,
        log.stream("tau_measured").select([name]).data[:max_samples, 0],
        color=COLORS["measured"],
        lw=0.6,
        label="measured",
    )
    ax.plot(t, mu, color=COLORS["model"], lw=0.8, label="predicted")
    sc = heldout_score(log)
    ax.set_title(f"{name}: held out (nMSE {sc.nmse[joint]:.3g}, within ±2σ {sc.coverage[joint]:.2f})")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("τ [N·m]")
    ax.legend(ncol=3, fontsize=6)
    return ax


def prediction_pages(path: Path, pdf, context) -> None:
    """A prediction log: per joint held-out nMSE, RMSE and ±2σ coverage (0.95 expected for a
    calibrated predictive std), then measured vs predicted with the band."""
    from diegocal.io import load_log

    log = load_log(path)
    sc = heldout_score(log)
    lines = [
        f"samples: {log.n_samples}   robot: {log.robot or '-'}",
        "",
        f"{'joint':20s} {'nMSE':>10} {'RMSE':>10} {'within ±2σ':>11}",
    ]
    lines += [
        f"{j:20s} {e:10.4g} {r:10.4g} {c:11.3f}"
        for j, e, r, c in zip(sc.channels, sc.nmse, sc.rmse, sc.coverage, strict=True)
    ]
    lines += ["", "within ±2σ: the fraction of measured torques inside the predicted mean ± 2 std", "(0.95 expected)."]
    save_page(pdf, text_page(f"Held-out prediction: {path.name}", lines))
    n = len(sc.channels)
    for start in range(0, n, MAX_JOINTS_PER_PAGE):
        joints = range(start, min(n, start + MAX_JOINTS_PER_PAGE))
        fig, axes = page(len(joints), 1, title=f"{path.name}: held out (±2σ)")
        for ax, j in zip(axes[:, 0], joints, strict=True):
            plot_prediction_band(log, j, ax=ax)
        save_page(pdf, fig)


# ----------------------------------------------------------------------------- pages
def summary_lines(summary: dict) -> list[str]:
    from diegocal.io.bundle import robot_of

    lines = [
        f"kind: {summary['kind']}   robot: {robot_of(summary)['name']}   samples: {summary['n_samples']}",
        f"inference: {summary['inference']}"
        + (f" ({summary['n_inducing']} inducing inputs)" if summary.get("n_inducing") else ""),
        f"GP inputs: {', '.join(summary.get('gp_inputs') or []) or '-'}",
        ("VFE lower bound on the log marginal likelihood" if summary.get("n_inducing") else "log marginal likelihood")
        + f": {summary['log_likelihood']:.6g}",
        "",
        "nMSE in-sample per joint:",
    ]
    lines += [f"  {j:20s} {v:.4g}" for j, v in summary["nmse_in_sample"].items()]
    lines += ["", "hyperparameters:"]
    hp = summary["hyperparameters"]
    if hp.get("sigma_w") is not None:
        lines.append(f"  sigma_w {hp['sigma_w']:.4g}")
    for j, entry in hp.items():
        if j == "sigma_w":
            continue
        parts = [f"sigma_v {entry['sigma_v']:.3g}"]
        if "sigma_z" in entry:
            parts.append(f"sigma_z {entry['sigma_z']:.3g}")
        if "guard_choice" in entry:
            parts.append(f"guard: {entry['guard_choice']}")
        if "n_inducing" in entry:
            parts.append(f"{entry['n_inducing']} inducing inputs (missing {entry['sparse_gap']:.2g} σ_v²)")
        lines.append(f"  {j}: " + ", ".join(parts))
        for name, ell in (entry.get("lengthscales") or {}).items():
            lines.append(f"      l {name:24s} {ell:.3g}")
    par = summary.get("parameters") or {}
    if par:
        lines += ["", f"base parameters ({len(par)}): value ± std"]
        lines += [f"  {k:24s} {v['value']:+.4g} ± {v['std']:.2g}" for k, v in list(par.items())[:40]]
        if len(par) > 40:
            lines.append(f"  ... {len(par) - 40} more in sgp.yaml")
    meta = summary.get("meta") or {}
    if meta:
        lines += ["", *(f"{k}: {v}" for k, v in meta.items())]
    return lines


def model_pages(path: Path, pdf) -> None:
    summary = load_summary(path)
    save_page(pdf, text_page(f"SGP model: {path.name}", summary_lines(summary), fontsize=7))
    model = load_model(path)
    n = model.robot.n_joints
    for start in range(0, n, MAX_JOINTS_PER_PAGE):
        joints = range(start, min(n, start + MAX_JOINTS_PER_PAGE))
        fig, axes = page(len(joints), 1, title=f"{path.name}: measured vs predicted (±2σ)")
        for ax, j in zip(axes[:, 0], joints, strict=True):
            plot_torque_band(model, j, ax=ax)
        save_page(pdf, fig)
        fig, axes = page(len(joints), 2, title=f"{path.name}: uncertainty in state space (§3.5.1)")
        for row, j in enumerate(joints):
            plot_angle_slice(model, j, ax=axes[row, 0])
            plot_uncertainty_map(model, j, ax=axes[row, 1])
        save_page(pdf, fig)


def pages(path: Path, pdf, context) -> None:
    dirs = model_dirs(path)
    if len(dirs) > 1:
        summaries = {p.name: load_summary(p) for p in dirs}
        fig, axes = page(2, 1, title=f"Model comparison: {Path(path).name}")
        plot_nmse_comparison(summaries, ax=axes[0, 0])
        axes[1, 0].axis("off")
        save_page(pdf, fig)
    for p in dirs:
        model_pages(p, pdf)


register_section(Section("sgp", recognise, pages, describe))
# a dynamics prediction is a log too: tried before the plain log section
register_section(Section("sgp prediction", is_prediction, prediction_pages, lambda p: {"log": str(p)}), before="log")
