"""The SGP section's opening (plain words and key numbers); its figures are in :mod:`diegocal.report.sgp`.

What was fitted on what (model kind, joints, samples, inference), how good it is in-sample and on
held-out logs given with ``diegocal report --heldout LOG`` (nMSE per joint and the share of
measured torques inside the predicted ±2σ band), and what is still open (joints without torque,
a held-out error far above the in-sample one). The report puts these on an opening page before
the section's own pages.
"""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np

from diegocal.errors import DiegocalError
from diegocal.report.layout import Column

KIND_WORDS = {
    "sgp": "semi-parametric (rigid-body and friction regression plus a Gaussian process on what it leaves)",
    "prgp": "parametric regression with a Gaussian-process residual",
    "pr": "parametric (rigid-body and friction regression)",
    "gp": "non-parametric (Gaussian process alone)",
}


@functools.lru_cache(maxsize=8)
def heldout_scores(path: str, heldout: tuple[str, ...]) -> tuple[str | None, int, dict]:
    """(held-out log, samples, {joint: (nMSE, share inside ±2σ)}) on the first held-out log of the
    model's robot with q and tau; (None, 0, {}) when there is none."""
    from diegocal.io import load_log
    from diegocal.io.bundle import load_bundle
    from diegocal.report.registry import ReportContext
    from diegocal.sgp import load_model, nmse

    context = ReportContext(heldout=tuple(map(Path, heldout)))
    for hpath in context.heldout_for(load_bundle(Path(path)).robot, ("q", "tau")):
        try:
            model = load_model(Path(path))
            log = load_log(hpath)
            pred = model.predict(log)
            measured = log.stream("tau").select(model.joint_names).data
        except DiegocalError:
            continue
        err = nmse(pred.tau, measured)
        inside = np.mean(np.abs(pred.tau - measured) <= 2 * pred.tau_std, axis=0)
        scores = {j: (float(e), float(c)) for j, e, c in zip(model.joint_names, err, inside, strict=True)}
        return str(hpath), log.n_samples, scores
    return None, 0, {}


def _models(path: Path) -> list[Path]:
    from diegocal.report.sgp import model_dirs

    return model_dirs(path)


def _scores(model: Path, context):
    return heldout_scores(str(model.resolve()), tuple(str(p) for p in context.heldout))


def abstract(path: Path, context) -> list[str]:
    from diegocal.io.bundle import robot_of
    from diegocal.sgp import load_summary

    out = []
    for model in _models(path):
        s = load_summary(model)
        joints = s.get("nmse_in_sample") or {}
        log = Path(str((s.get("meta") or {}).get("log") or s.get("log") or "?")).name
        inference = s.get("inference", "?") + (f", {s['n_inducing']} inducing inputs" if s.get("n_inducing") else "")
        text = (
            f"{model.name}: a {KIND_WORDS.get(s.get('kind'), s.get('kind'))} torque model of robot "
            f"{robot_of(s)['name']} "
            f"was fitted to {len(joints)} joint(s) from {s.get('n_samples')} samples of {log} ({inference}). "
            f"In-sample nMSE (squared error over the torque's variance): "
            + ", ".join(f"{j} {v:.2g}" for j, v in joints.items())
            + "."
        )
        hpath, n, held = _scores(model, context)
        if held:
            text += (
                f" On held-out data ({Path(hpath).name}, {n} samples) nMSE "
                + ", ".join(f"{j} {e:.2g}" for j, (e, _) in held.items())
                + "; measured torques inside the predicted ±2σ band: "
                + ", ".join(f"{j} {100 * c:.0f} %" for j, (_, c) in held.items())
                + " (95 % expected)."
            )
            worst = max(held, key=lambda j: held[j][0] / max(joints.get(j, np.inf), 1e-12))
            ratio = held[worst][0] / max(joints.get(worst, np.inf), 1e-12)
            if ratio > 3:
                text += (
                    f" Still open: on {worst} the held-out error is {ratio:.0f} times the in-sample one, so the "
                    "model has learnt more of the training session than carries over."
                )
        else:
            text += " No held-out log was given (diegocal report ... --heldout LOG): in-sample numbers only."
        missing = s.get("joints_without_tau") or []
        if missing:
            text += f" Not fitted (no measured torque): {', '.join(missing)}."
        out.append(text)
    return out


def headline(path: Path, context) -> str:
    from diegocal.sgp import load_summary

    parts = []
    for model in _models(path):
        s = load_summary(model)
        nm = list((s.get("nmse_in_sample") or {}).values())
        text = f"{model.name}: {len(nm)} joint(s), nMSE in-sample ≤ {max(nm):.2g}"
        _, _, held = _scores(model, context)
        if held:
            cover = [100 * c for _, c in held.values()]
            text += (
                f", held-out ≤ {max(e for e, _ in held.values()):.2g}, ±2σ covers {min(cover):.0f}-{max(cover):.0f} %"
            )
        parts.append(text)
    return "; ".join(parts)


def key_table(path: Path, context) -> tuple[list[Column], list[list]]:
    """One row per model and joint: in-sample and held-out nMSE, ±2σ coverage, noise level."""
    from diegocal.sgp import load_summary

    columns = [
        Column("model", align="left"),
        Column("joint", align="left"),
        Column("nMSE in-sample"),
        Column("nMSE held-out"),
        Column("inside ±2σ, held-out", "%"),
        Column("noise σ_v", "N·m"),
        Column("guard", align="left"),
    ]
    rows = []
    for model in _models(path):
        s = load_summary(model)
        _, _, held = _scores(model, context)
        hyper = s.get("hyperparameters") or {}
        for j, v in (s.get("nmse_in_sample") or {}).items():
            e, c = held.get(j, (None, None))
            h = hyper.get(j) or {}
            sigma = h.get("sigma_v")
            rows.append(
                [
                    model.name,
                    j,
                    f"{v:.3g}",
                    "–" if e is None else f"{e:.3g}",
                    "–" if c is None else f"{100 * c:.0f}",
                    "–" if sigma is None else f"{sigma:.3g}",
                    h.get("guard_choice", "–"),
                ]
            )
    return columns, rows
