"""The SGP section's figures (thesis ch. 3): measured vs predicted torque with the ±2σ band,
the prediction along a joint's angle (Fig. 3.10) with the band's width beside it, the latent std
over (q, qd) (§3.5.1), the nMSE of several models. Pages are assembled in :mod:`diegocal.report.sgp`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from diegocal.report.sgp_text import heldout, heldout_score, torque_unit
from diegocal.report.style import COLORS, axes_or_new, headroom
from diegocal.sgp import load_summary

MAX_SAMPLES = 1500  # a time series longer than this shows its first MAX_SAMPLES samples
SLICE_POINTS = 150


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


def window(n: int) -> tuple[slice, str]:
    """The samples a time series shows, and the words for the axis."""
    if n <= MAX_SAMPLES:
        return slice(0, n), f"{n} samples"
    return slice(0, MAX_SAMPLES), f"first {MAX_SAMPLES} of {n} samples"


def training_prediction(model):
    """The model's prediction of its first MAX_SAMPLES training samples (TorquePrediction)."""
    n = model.robot.n_joints
    U = model.U_[window(len(model.U_))[0]]
    time = None if model.time_ is None else model.time_[: len(U)]
    return model.predict_arrays(U[:, :n], U[:, n : 2 * n], U[:, 2 * n :], time)


def plot_torque_band(model, k: int, ax=None, pred=None):
    """Training log: measured vs predicted torque of fitted joint ``k`` with ±2σ (eq. 3.20)."""
    ax = axes_or_new(ax)
    pred = training_prediction(model) if pred is None else pred
    shown, words = window(len(model.U_))
    m = len(pred.tau)
    has_time = model.time_ is not None
    x = model.time_[:m] if has_time else np.arange(m)
    kind = model.options.kind
    par = pred.tau_parametric[:, k] if kind in ("sgp", "prgp") else None
    plot_band(x, model.tau_[shown, k], pred.tau[:, k], pred.tau_std[:, k], ax, par, label="mean")
    name = model.joint_names[k]
    ax.set_title(f"{name}: training log (nMSE {float(model.nmse_in_sample_[k]):.3g})")
    ax.set_xlabel(f"time [s]  ({words})" if has_time else f"training sample  ({words})")
    ax.set_ylabel(f"τ {name} [{torque_unit(model, name)}]")
    return ax


def plot_heldout_band(model, held, k: int, ax=None):
    """Held-out log (:class:`~diegocal.report.sgp_text.HeldOut`): measured vs predicted with ±2σ."""
    ax = axes_or_new(ax)
    shown, words = window(len(held.time))
    name = model.joint_names[k]
    par = held.parametric[shown, k] if model.options.kind in ("sgp", "prgp") else None
    plot_band(
        held.time[shown],
        held.measured[shown, k],
        held.predicted[shown, k],
        held.std[shown, k],
        ax,
        par,
        label="mean",
    )
    e, _, c = held.of(name)
    ax.set_title(f"{name}: held-out log (nMSE {e:.3g}, {100 * c:.0f} % in ±2σ)")
    ax.set_xlabel(f"time [s]  ({words})")
    ax.set_ylabel(f"τ {name} [{torque_unit(model, name)}]")
    return ax


def _slice_states(model, r: int, grid: np.ndarray, velocity: np.ndarray | None = None):
    """States along robot joint ``r``'s angle (and velocity), the other inputs at their training mean."""
    n = model.robot.n_joints
    U = np.repeat(model.U_.mean(0)[None], len(grid), axis=0)
    U[:, r] = grid
    if velocity is not None:
        U[:, n + r] = velocity
    return U[:, :n], U[:, n : 2 * n], U[:, 2 * n :]


@dataclass(frozen=True)
class AngleSlice:
    """A model's prediction along one joint's angle, every other input at its training mean (thesis
    Fig. 3.10): grid (G,) rad, mean and latent std (G,) in the joint's torque unit, the angles seen
    in training (N,) rad; ``gp``: whether a Gaussian process acts on this joint (not switched off)."""

    joint: str
    kind: str
    unit: str
    grid: np.ndarray
    mean: np.ndarray
    std: np.ndarray
    seen: np.ndarray
    gp: bool

    def growth(self) -> tuple[float, float | None]:
        """(latent std among the training angles (median), largest latent std beyond them, or None
        when the training angles span the whole slice)."""
        inside = (self.grid >= self.seen.min()) & (self.grid <= self.seen.max())
        at_data = float(np.median(self.std[inside])) if inside.any() else float(self.std.min())
        return at_data, (float(self.std[~inside].max()) if (~inside).any() else None)

    def words(self) -> str:
        """How the band's width changes away from the training angles, in words, with the numbers."""
        at_data, far = self.growth()
        text = f"{self.joint}: 2σ is {2 * at_data:.2g} {self.unit} among the training angles"
        if far is None:
            text += ", which span the whole range shown"
        else:
            ratio = far / max(at_data, 1e-300)
            how = "grows away from the data" if ratio >= GROWS else "stays about flat"
            text += f" and up to {2 * far:.2g} {self.unit} beyond them (×{ratio:.1f}): it {how}"
        if not self.gp:
            text += " (no Gaussian process on this joint: the band is the parametric weights' uncertainty alone)"
        return text


#: The band "grows away from the data" when its width beyond the training angles reaches this
#: multiple of its width among them.
GROWS = 1.5


def angle_slice(model, k: int, gp: bool = True) -> AngleSlice:
    """Fitted joint ``k``'s :class:`AngleSlice` over its range (within ±π)."""
    r = model.rows[k]
    lo, hi = max(model.robot.lower[r], -np.pi), min(model.robot.upper[r], np.pi)
    grid = np.linspace(lo, hi, SLICE_POINTS)
    pred = model.predict_arrays(*_slice_states(model, r, grid))
    name = model.joint_names[k]
    return AngleSlice(
        name, model.options.kind, torque_unit(model, name), grid, pred.tau[:, k], pred.tau_std_latent[:, k],
        model.U_[:, r], gp,
    )  # fmt: skip


def plot_angle_slice(sl: AngleSlice, ax=None):
    """Thesis Fig. 3.10: prediction ±2σ (latent) along q_j, the other inputs at their training mean."""
    ax = axes_or_new(ax)
    mu, sd = sl.mean, sl.std
    ax.fill_between(sl.grid, mu - 2 * sd, mu + 2 * sd, color=COLORS["band"], alpha=0.25, lw=0, label="±2σ (latent)")
    ax.plot(sl.grid, mu, color=COLORS["model"], label=f"{sl.kind} mean")
    ax.plot(
        sl.seen,
        np.full(len(sl.seen), 0.03),
        "|",
        color=COLORS["measured"],
        ms=5,
        alpha=0.3,
        transform=ax.get_xaxis_transform(),
        label=f"training q ({len(sl.seen)})",
    )
    ax.ticklabel_format(axis="y", useOffset=False)
    headroom(ax, 0.45)
    ax.set_xlabel(f"q.{sl.joint} [rad]")
    ax.set_ylabel(f"τ {sl.joint} [{sl.unit}]")
    ax.set_title(f"{sl.joint}: along its angle (Fig. 3.10)")
    ax.legend(fontsize=6, loc="upper right", ncol=3)
    return ax


def plot_slice_width(sl: AngleSlice, ax=None):
    """The width of :func:`plot_angle_slice`'s band, 2 latent std, along the angle, on an axis from
    zero scaled to it (visible however narrow the band is beside the torque); grey: the range of
    angles seen in training."""
    ax = axes_or_new(ax)
    ax.axvspan(sl.seen.min(), sl.seen.max(), color="0.88", lw=0, label="training angles")
    ax.plot(sl.grid, 2 * sl.std, color=COLORS["band"], label="2σ (latent)")
    ax.set_ylim(0, 1.3 * max(2 * float(sl.std.max()), 1e-12))
    ax.set_xlim(sl.grid[0], sl.grid[-1])
    ax.set_xlabel(f"q.{sl.joint} [rad]")
    ax.set_ylabel(f"2σ [{sl.unit}]")
    ax.legend(fontsize=6, loc="upper right", ncol=2)
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
    ax.figure.colorbar(mesh, ax=ax, label=f"latent std [{torque_unit(model, name)}]")
    ax.plot(q_seen, qd_seen, ".", color="w", ms=1, alpha=0.5, label=f"training samples ({len(q_seen)})")
    ax.set_xlabel(f"q.{name} [rad]")
    ax.set_ylabel(f"qd.{name} [rad/s]")
    ax.set_title(f"{name}: uncertainty over (q, qd)")
    ax.legend(fontsize=6, loc="upper right", markerscale=4, facecolor="0.45", labelcolor="w")
    return ax


def plot_nmse_comparison(models: list[Path], context, ax=None):
    """Grouped bars: nMSE per joint (groups) and model (colours), in-sample (hatched) and held-out
    (solid) when a held-out log was given; log scale."""
    ax = axes_or_new(ax)
    summaries = {m.name: load_summary(m) for m in models}
    helds = {m.name: heldout(m, context) for m in models}
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


def plot_prediction_band(log, k: int, ax=None, sc=None):
    """A prediction log: measured vs predicted torque of joint ``k`` with the ±2σ band (eq. 3.20)."""
    ax = axes_or_new(ax)
    pred = log.stream("tau")
    name = pred.names[k]
    shown, words = window(log.n_samples)
    sd = log.stream("tau_std").select([name]).data[shown, 0]
    measured = log.stream("tau_measured").select([name]).data[shown, 0]
    plot_band(log.time[shown], measured, pred.data[shown, k], sd, ax, label="predicted mean")
    sc = heldout_score(log) if sc is None else sc
    ax.set_title(f"{name}: nMSE {sc.nmse[k]:.3g}, {100 * sc.coverage[k]:.0f} % inside ±2σ")
    ax.set_xlabel(f"time [s]  ({words})")
    ax.set_ylabel(f"τ {name} [N·m]")
    return ax
