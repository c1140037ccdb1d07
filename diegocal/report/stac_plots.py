"""The STAC section's plots (thesis ch. 2 figures) and the data they are drawn from.

Marker positions before/after on the robot skeleton (Figs. 2.8-2.9), convergence of the cost
(``fit.history``), noise levels, residual histograms per sensor type. The section's pages, tables
and words are in :mod:`diegocal.report.stac_pages`.
"""

from __future__ import annotations

import numpy as np

from diegocal.report.style import COLORS, axes_or_new
from diegocal.robot.batch import BatchKinematics
from diegocal.stac.calibration import READING_UNITS, Calibration
from diegocal.stac.model import MARKERS, Observation


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


def pot_units_pooled(cal: Calibration) -> dict:
    """{pot type: unit} of the pot types whose σ ``fit.history``'s ``sigma_pots`` pools (their RMS)."""
    return {g: READING_UNITS.get(g, "sensor unit") for g in cal.sigma_by_group if g != MARKERS}


def plot_sigma(cal: Calibration, ax=None):
    """Noise levels per sensor type over the iterations (dynamic variance adjustment, §2.3.5).

    ``fit.history`` keeps the markers' σ and the RMS of the pot types' σ: drawn as one line when
    every pot type reads in one unit; when they do not (rotary pots in V, encoders in rad) that RMS
    has no unit, and each type's final σ is drawn at the last iteration instead."""
    ax = axes_or_new(ax)
    it = [h["iteration"] for h in cal.history]
    units = pot_units_pooled(cal)
    one = set(units.values()) if units else {"V"}
    if len(one) == 1:
        ax.semilogy(it, [h.get("sigma_pots") or np.nan for h in cal.history], label=f"pots ({one.pop()})")
    else:
        for k, (g, unit) in enumerate(units.items()):
            ax.semilogy(it[-1:], [cal.sigma_by_group[g]], "sd^v"[k % 4], label=f"{g} ({unit}), final")
    ax.semilogy(it, [h.get("sigma_markers") or np.nan for h in cal.history], label="markers (m)")
    shown = ", ".join(dict.fromkeys([*units.values(), "m"])) if units else "V, m"
    ax.set_xlabel("iteration")
    ax.set_ylabel(f"noise σ [each type's unit: {shown}]")
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
    """{type: (residuals, unit)} of the log under the calibration at the tracked q: pots reading
    minus model in their type's unit (:data:`READING_UNITS`: V, rad for encoders), markers the
    distance between measured and modelled position ("m (distance)")."""
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
            out[g] = (rp[:, obs.kinds == g].ravel(), READING_UNITS.get(g, "sensor unit"))
    return out
