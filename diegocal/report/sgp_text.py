"""The SGP section's data and words: the models a path holds, their scores on held-out logs, and
how good they are in plain words; its tables of what was fitted are in
:mod:`diegocal.report.sgp_tables`, its figures in :mod:`diegocal.report.sgp_plots`, its pages in
:mod:`diegocal.report.sgp`.

What was fitted on what (model kind, joints, samples, inference), how good it is in-sample and on
held-out logs given with ``diegocal report --heldout LOG`` (nMSE, RMSE and the share of measured
torques inside the predicted ±2σ band per joint), what the guard chose and what is still open; the
per-joint table (a directory of several models gets one comparison table); a prediction log's
scores, table and verdict.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from diegocal.errors import DiegocalError
from diegocal.evaluate import COVERAGE_BAND, score
from diegocal.io import load_log
from diegocal.io.bundle import load_bundle, robot_of
from diegocal.report.layout import Column
from diegocal.report.registry import ReportContext
from diegocal.report.sgp_tables import GUARD_NOTE, GUARD_WORDS, SLIDE_NOTE, model_kind, number, slides
from diegocal.sgp import is_model_dir, load_model, load_summary
from diegocal.sgp.store import region_text, unconverged

#: The streams a held-out log needs: the joint angles (and their rates) and the measured torque.
HELDOUT_STREAMS = ("q", "tau")

KIND_WORDS = {
    "sgp": "semi-parametric (rigid-body and friction regression plus a Gaussian process on what it leaves)",
    "prgp": "parametric regression with a Gaussian-process residual",
    "pr": "parametric (rigid-body and friction regression)",
    "gp": "non-parametric (Gaussian process alone)",
}
#: nMSE (squared error over the torque's variance) a verdict calls good, fair: above, poor.
NMSE_GOOD, NMSE_FAIR = 0.01, 0.1


def model_dirs(path: Path) -> list[Path]:
    """The model directories a path stands for: itself, or its model sub-directories."""
    path = Path(path)
    if is_model_dir(path):
        return [path]
    if path.is_dir():
        return sorted(p for p in path.iterdir() if is_model_dir(p))
    return []


@dataclass(frozen=True)
class HeldOut:
    """A model's prediction of one held-out log: ``score`` per joint (nMSE, RMSE, coverage of ±2σ),
    and the arrays the figures need: time (T,) s; measured, predicted, its std and the parametric
    part alone (T, n) N·m."""

    log: str
    score: object  # diegocal.evaluate.Score
    time: np.ndarray
    measured: np.ndarray
    predicted: np.ndarray
    std: np.ndarray
    parametric: np.ndarray
    train_rmse: dict = field(default_factory=dict)  # joint -> the model's in-sample RMSE

    def of(self, joint: str) -> tuple[float, float, float] | None:
        """(nMSE, RMSE, share inside ±2σ) of a joint."""
        sc = self.score
        if joint not in sc.channels:
            return None
        k = sc.channels.index(joint)
        return float(sc.nmse[k]), float(sc.rmse[k]), float(sc.coverage[k])


@functools.lru_cache(maxsize=8)
def heldout_prediction(path: str, heldout: tuple[str, ...]) -> HeldOut | None:
    """The model at ``path`` on the first held-out log of its robot with q and tau, or None; a
    prediction log (``diegocal predict``'s output) is scored against its ``tau_measured``."""
    context = ReportContext(heldout=tuple(map(Path, heldout)))
    for hpath in context.heldout_for(load_bundle(Path(path)).robot, HELDOUT_STREAMS):
        try:
            model = load_model(Path(path))
            log = load_log(hpath)
            pred = model.predict(log)
            # a prediction log (predict's output) holds the prediction in tau, the torque in tau_measured
            torque = "tau_measured" if "tau_measured" in log.streams else "tau"
            measured = log.stream(torque).select(model.joint_names).data
        except DiegocalError:
            continue
        sc = score(measured, pred.tau, model.joint_names, std=pred.tau_std, unit="N·m")
        # the in-sample nMSE sgp.yaml holds (a loaded model would predict its training log again)
        nmse = load_summary(Path(path))["nmse_in_sample"]
        spread = np.nanvar(model.tau_, axis=0)  # × the training torque's variance
        rmse = np.sqrt(np.array([nmse[j] for j in model.joint_names], float) * spread)
        train = dict(zip(model.joint_names, rmse.tolist(), strict=True))
        return HeldOut(str(hpath), sc, log.time, measured, pred.tau, pred.tau_std, pred.tau_parametric, train)
    return None


def heldout(model: Path, context) -> HeldOut | None:
    return heldout_prediction(str(Path(model).resolve()), tuple(str(p) for p in context.heldout))


def heldout_needs(path: Path) -> list:
    """Each model's robot and the streams a held-out log needs to score it."""
    return [(load_bundle(m).robot, HELDOUT_STREAMS) for m in model_dirs(path)]


def heldout_score(log):
    """:class:`diegocal.evaluate.Score` of a prediction log: nMSE, RMSE, ±2σ coverage per joint."""
    pred = log.stream("tau")
    measured = log.stream("tau_measured").select(pred.names).data
    std = log.stream("tau_std").select(pred.names).data
    return score(measured, pred.data, pred.names, std=std, unit="N·m")


def prismatic_joints(robot) -> frozenset:
    """Names of the robot's prismatic joints (their torque is a force, N)."""
    out = set()
    for name in robot.joint_names:
        kind = robot.model.joints[robot.model.getJointId(name)].shortname().replace("JointModel", "")
        if kind in ("PX", "PY", "PZ", "PrismaticUnaligned"):
            out.add(name)
    return frozenset(out)


def torque_unit(model, joint: str) -> str:
    """N for a prismatic joint's force, N·m for a revolute joint's torque."""
    return "N" if joint in prismatic_joints(model.robot) else "N·m"


# ----------------------------------------------------------------------------- words
def verdict(nmse: float, coverage: float | None = None) -> str:
    """A few words on one joint's held-out numbers."""
    fit = "good" if nmse < NMSE_GOOD else "fair" if nmse < NMSE_FAIR else "poor" if nmse < 1 else "useless"
    if coverage is None or not np.isfinite(coverage):
        return fit
    lo, hi = COVERAGE_BAND
    if coverage < lo:
        return f"{fit}; ±2σ too narrow"
    if coverage > hi:
        return f"{fit}; ±2σ too wide"
    return f"{fit}; ±2σ right"


def _joint_list(values: dict, fmt: str = ".2g", scale: float = 1.0, suffix: str = "") -> str:
    return ", ".join(f"{j} {scale * v:{fmt}}{suffix}" for j, v in values.items())


def uncertainty_words(coverage: dict) -> str:
    """Whether the predicted ±2σ band is as wide as the errors it should cover, in words."""
    lo, hi = COVERAGE_BAND
    narrow = [j for j, c in coverage.items() if c < lo]
    wide = [j for j, c in coverage.items() if c > hi]
    parts = []
    if narrow:
        parts.append(
            f"too narrow on {', '.join(narrow)} (the model is surer than its errors warrant: an effect "
            "it does not model, or a noise level learnt too low)"
        )
    if wide:
        parts.append(f"too wide on {', '.join(wide)} (the model is more cautious than it needs to be)")
    rest = [j for j in coverage if j not in narrow and j not in wide]
    if rest:
        parts.append(f"about right on {', '.join(rest)}")
    return "the ±2σ band is " + "; ".join(parts)


#: A held-out RMSE this many times the in-sample one on a joint is said (the model learnt the session)
WORSE_HELDOUT = 2.0
#: A joint whose learnt noise σ_v is this many times the median of the model's other joints: its
#: ±2σ band covers the data because the model's error is that large there, not because it is right.
NOISY = 10.0
#: ... and whose relative error, √(in-sample nMSE), is this many times theirs: a shoulder that carries
#: sixty times a wrist's torque has a noisier torque in N·m and is not the worse fitted for it
WORSE = 3.0


def noisy_joints(hyper: dict, nmse: dict | None = None) -> dict:
    """joint -> (its σ_v, the other joints' median σ_v) where σ_v is NOISY times that median or more
    (a model of three or more joints) and, given the in-sample ``nmse`` per joint, its relative error
    √nMSE is WORSE times the others' median too (noise in N·m grows with the torque a joint carries)."""
    sigma = {j: float(h["sigma_v"]) for j, h in hyper.items() if isinstance(h, dict) and h.get("sigma_v")}
    rel = {j: float(v) ** 0.5 for j, v in (nmse or {}).items() if v is not None and j in sigma}
    out = {}
    for j, v in sigma.items():
        others = [w for k, w in sigma.items() if k != j]
        if len(others) >= 2 and v >= NOISY * float(np.median(others)) > 0:
            peers = [w for k, w in rel.items() if k != j]
            if j in rel and peers and rel[j] < WORSE * float(np.median(peers)):
                continue
            out[j] = (v, float(np.median(others)))
    return out


def noisy_words(hyper: dict, nmse: dict | None = None) -> str:
    """A sentence on each joint whose learnt noise is far above its siblings' ("" when none is)."""
    return "".join(
        f" But on {j} the noise the model learnt, σ_v {v:.3g}, is {v / rest:.0f} times the other joints' median "
        f"({rest:.3g}): the model's error is that large there, and its ±2σ band wide because of it, not because "
        "the model is right; an effect the model lacks is likely (diegocal diagnose names it), unless that "
        "joint's sensor is that noisy."
        for j, (v, rest) in noisy_joints(hyper, nmse).items()
    )


#: A kept GP whose length-scale in an input is under this share of the input's training std follows
#: detail finer than most effects of a joint's state: this session's path, or a fine effect (cogging).
FINE = 0.1


def fine_inputs(hyper: dict) -> dict:
    """joint -> {input: length-scale in training stds} of the joints whose kept GP (the guard's
    choice not "parametric") varies over less than :data:`FINE` of an input's spread."""
    out = {}
    for j, h in hyper.items():
        if not isinstance(h, dict) or h.get("guard_choice") in (None, "parametric"):
            continue
        fine = {k: float(v) for k, v in (h.get("lengthscales_std") or {}).items() if v < FINE}
        if fine:
            out[j] = fine
    return out


def fine_words(hyper: dict) -> str:
    """A sentence on each joint whose kept GP follows fine detail ("" when none does)."""
    def spreads(fine: dict) -> str:
        return " and ".join(f"{v:.2g} of {k}'s" for k, v in fine.items())

    return "".join(
        f" On {j} the GP kept varies over {spreads(fine)} training "
        "spread: detail of this session's path, which another motion may not share, or a fine effect (cogging); "
        "its cross-validated gain comes from blocks of this path: check it on another session (diegocal predict)."
        for j, fine in fine_inputs(hyper).items()
    )


def worse_than_mean_words(nmse_in_sample: dict) -> str:
    """A sentence on the joints a model fits worse than their mean torque on its own training data
    (in-sample nMSE 1 or more; "" when none does)."""
    worse = [j for j, v in nmse_in_sample.items() if v is not None and v >= 1.0]
    if not worse:
        return ""
    return (
        f" On {', '.join(worse)} the model does worse than the mean torque on its own training data: the "
        "parameters it shares with the other joints, fitted to all at once, do not describe that joint's "
        "measured effort (how it is measured, or a model of its own, is the next thing to look at)."
    )


def model_paragraphs(model: Path, context) -> list[str]:
    """One model in plain words: what was fitted on what and how good it is; what the guard did."""
    s = load_summary(model)
    kind = model_kind(s)
    joints = s.get("nmse_in_sample") or {}
    log = Path(str((s.get("meta") or {}).get("log") or s.get("log") or "?")).name
    inference = s.get("inference", "?") + (f", {s['n_inducing']} inducing inputs" if s.get("n_inducing") else "")
    text = (
        f"{model.name}: a {KIND_WORDS.get(kind, kind)} torque model of robot {robot_of(s)['name']}, fitted to "
        f"{len(joints)} joint(s) from {s.get('n_samples')} samples of {log} ({inference} inference). "
        "In-sample nMSE (squared error over the torque's variance: 0 is perfect, 1 no better than the mean "
        "torque): " + _joint_list(joints) + "."
    )
    text += worse_than_mean_words(joints)
    if s.get("converged") is False:  # sgp-fit's own words for it
        text += (
            f" Not converged: {unconverged(s)}; the numbers below are those of a fit still moving "
            "(sgp-fit --max-iterations)."
        )
    held = heldout(model, context)
    if held is not None:
        scores = {j: held.of(j) for j in joints if held.of(j) is not None}
        text += (
            f" On held-out data ({Path(held.log).name}, {len(held.time)} samples) nMSE "
            + _joint_list({j: v[0] for j, v in scores.items()})
            + "; measured torques inside the predicted ±2σ band: "
            + _joint_list({j: v[2] for j, v in scores.items()}, ".0f", 100, " %")
            + " (95 % expected): "
            + uncertainty_words({j: v[2] for j, v in scores.items()})
            + "."
        )
        inside = {j: held.train_rmse.get(j) for j in scores}  # RMSE, N·m: nMSEs divide by each log's spread
        ratios = {j: v[1] / inside[j] for j, v in scores.items() if inside[j] and inside[j] > 0}
        worst = max(ratios, key=ratios.get) if ratios else None
        if worst is not None and ratios[worst] > WORSE_HELDOUT:
            text += (
                f" Still open: on {worst} the held-out RMSE, {scores[worst][1]:.3g} N·m, is {ratios[worst]:.1f} times "
                f"the in-sample one ({inside[worst]:.3g}), so the model has learnt more of the training session than "
                "carries over."
            )
    else:
        text += " No held-out log was given (diegocal report ... --heldout LOG): in-sample numbers only."
    text += noisy_words(s.get("hyperparameters") or {}, joints) + fine_words(s.get("hyperparameters") or {})
    out = [text]
    more = []
    hyper = s.get("hyperparameters") or {}
    choices = {j: (hyper.get(j) or {}).get("guard_choice") for j in joints}
    kept = [j for j, c in choices.items() if c and c != "parametric"]
    dropped = [j for j, c in choices.items() if c == "parametric"]
    if kept or dropped:
        words = "The guard (cross-validation on contiguous blocks of the training log) "
        if kept:
            words += f"kept the Gaussian process on {', '.join(kept)}"
        if dropped:
            words += (" and " if kept else "") + (
                f"switched it off on {', '.join(dropped)}, where it did not predict unseen blocks better than the "
                "parametric part alone (by one standard error and 2 % of its error)"
            )
        more.append(words + ".")
    gaps = {j: h["sparse_gap"] for j, h in hyper.items() if isinstance(h, dict) and "sparse_gap" in h}
    if gaps:
        more.append(
            f"Sparse inference misses at most {max(gaps.values()):.2g} σ_v² of prior variance per training sample "
            "(0: as good as exact inference)."
        )
    missing = s.get("joints_without_tau") or []
    if missing:
        more.append(f"Not fitted (no measured torque): {', '.join(missing)}.")
    if more:
        out.append(" ".join(more))
    return out


def comparison_paragraph(models: list[Path], context) -> str:
    """A directory of models in plain words: which model predicts each joint best."""
    summaries = {m.name: load_summary(m) for m in models}
    logs = {Path(str((s.get("meta") or {}).get("log") or s.get("log") or "?")).name for s in summaries.values()}
    kinds = ", ".join(f"{name} ({model_kind(s)})" for name, s in summaries.items())
    text = f"A comparison of {len(models)} torque models fitted to {', '.join(sorted(logs))}: {kinds}."
    held = {m.name: heldout(m, context) for m in models}
    joints = list(next(iter(summaries.values())).get("nmse_in_sample") or {})
    if all(h is not None for h in held.values()):
        where = f"on held-out data ({Path(next(iter(held.values())).log).name})"
        err = {name: {j: (h.of(j) or (np.inf,))[0] for j in joints} for name, h in held.items()}
    else:
        where = "in-sample (no held-out log was given)"
        err = {name: dict(s.get("nmse_in_sample") or {}) for name, s in summaries.items()}
    best = []
    for j in joints:
        name = min(err, key=lambda n: err[n].get(j, np.inf))
        best.append(f"{j} {name} ({err[name].get(j, np.nan):.2g})")
    return text + f" Lowest nMSE {where}: " + ", ".join(best) + "."


def abstract(path: Path, context) -> list[str]:
    models = model_dirs(path)
    out = [comparison_paragraph(models, context)] if len(models) > 1 else []
    for model in models:
        out += model_paragraphs(model, context)
    return out


def headline(path: Path, context) -> str:
    parts = []
    for model in model_dirs(path):
        s = load_summary(model)
        nm = list((s.get("nmse_in_sample") or {}).values())
        text = f"{model.name}: {len(nm)} joint(s), nMSE in-sample ≤ {max(nm):.2g}"
        held = heldout(model, context)
        if held is not None:
            cover = 100 * held.score.coverage
            text += f", held-out ≤ {np.max(held.score.nmse):.2g}, ±2σ covers {cover.min():.0f}-{cover.max():.0f} %"
        parts.append(text)
    return "; ".join(parts)


# ----------------------------------------------------------------------------- tables
def joint_table(models: list[Path], context) -> tuple[list[Column], list[list], list[str]]:
    """Per joint (and model, for a comparison): nMSE in-sample and held-out, held-out RMSE and ±2σ
    coverage, the guard's choice, σ_v, σ_z and, for sparse fits, inducing inputs and missed variance."""
    summaries = {m: load_summary(m) for m in models}
    helds = {m: heldout(m, context) for m in models}
    any_held = any(h is not None for h in helds.values())
    entries = [h for s in summaries.values() for h in (s.get("hyperparameters") or {}).values() if isinstance(h, dict)]
    sparse = any("n_inducing" in h for h in entries)
    columns = [Column("model", align="left")] if len(models) > 1 else []
    columns += [Column("joint", align="left"), Column("nMSE\nin-sample")]
    if any_held:
        columns += [Column("nMSE\nheld-out"), Column("RMSE\nheld-out", "N·m"), Column("inside ±2σ", "%")]
    columns += [Column("guard's\nchoice", align="left"), Column("noise σ_v", "N·m"), Column("GP scale\nσ_z", "N·m")]
    if sparse:
        columns += [Column("inducing\ninputs"), Column("missed\nvariance", "σ_v²")]
    rows = []
    for m, s in summaries.items():
        hyper = s.get("hyperparameters") or {}
        kind = model_kind(s)
        for j, v in (s.get("nmse_in_sample") or {}).items():
            h = hyper.get(j) or {}
            row = [m.name] if len(models) > 1 else []
            row += [j, number(v)]
            if any_held:
                sc = helds[m].of(j) if helds[m] is not None else None
                row += ["–", "–", "–"] if sc is None else [number(sc[0]), number(sc[1]), f"{100 * sc[2]:.0f}"]
            choice = h.get("guard_choice")
            guard = GUARD_WORDS.get(choice, choice) if choice else ("no GP" if kind == "pr" else "GP (no guard)")
            guard += region_text(h)
            row += [guard, number(h.get("sigma_v")), number(h.get("sigma_z"))]
            if sparse:
                row += [str(h["n_inducing"]) if "n_inducing" in h else "exact", number(h.get("sparse_gap"), ".2g")]
            rows.append(row)
    notes = [
        "nMSE: mean squared error over the variance of the measured torque (thesis §3.4.2; 0 is perfect, 1 no "
        "better than predicting the mean torque). "
        + (
            "Held-out: on the first --heldout log of the model's robot; inside ±2σ: the share of measured torques "
            "within the predicted mean ± 2 predictive std (95 % expected). "
            if any_held
            else "No held-out log was given (diegocal report ... --heldout LOG). "
        )
        + "σ_v: the sensor noise std the model learnt; σ_z: the GP's prior std (near 0: the GP does nothing)."
        + (" Missed variance: the prior variance per sample that the inducing inputs do not capture." if sparse else "")
    ]
    sliding = sorted({j for s in summaries.values() for j in slides(s)})
    if sliding:
        notes.append(SLIDE_NOTE.format(", ".join(sliding)))
    if any(h.get("guard_choice") for h in entries):
        notes.append(GUARD_NOTE)
    if any(region_text(h) for h in entries):
        notes.append(
            "'cut at q ≥ c': the Gaussian process (the second stage's; with 'GP with an onset', the one learnt with "
            "the parametric part) is two, one below that angle of the joint and one above it, with nothing shared "
            "across (a friction confined to part of the range). Where the two stages are cut, their cross-validated "
            "nMSE, and 'parametric only' for that joint, come from every training sample outside each block. "
            "sgp-fit --no-region never cuts."
        )
    return columns, rows, notes


# ----------------------------------------------------------------------------- predictions
def prediction_paragraphs(path: Path, log, sc) -> list[str]:
    """A `diegocal predict` log of a torque model in plain words: what it holds, how good, verdict."""
    names = list(sc.channels)
    nm = dict(zip(names, sc.nmse, strict=True))
    cover = dict(zip(names, sc.coverage, strict=True))
    robot = f" of robot {log.robot}" if log.robot else ""
    source = log.source or {}
    if source.get("model") and source.get("log"):
        made = (
            f" by model {Path(source['model']).name} for {log.n_samples} samples ({log.duration:.3g} s) of log "
            f"{Path(source['log']).name}, beside the torques measured in it."
        )
    else:
        made = (
            f" for {log.n_samples} samples ({log.duration:.3g} s) of a log, beside the torques measured in it. "
            "The file does not name the model or the log it was made from."
        )
    text = (
        f"{Path(path).name}: the torques of {len(names)} joint(s){robot} predicted by diegocal predict{made}"
        " nMSE (squared error over the measured torque's variance: "
        "0 is perfect, 1 no better than the mean torque): "
        + _joint_list(nm)
        + "; RMSE "
        + _joint_list(dict(zip(names, sc.rmse, strict=True)), ".3g", 1.0, " N·m")
        + "; measured torques inside the predicted ±2σ band "
        + _joint_list(cover, ".0f", 100, " %")
        + " (95 % expected)."
    )
    good = [j for j, v in nm.items() if v < NMSE_GOOD]
    poor = [j for j, v in nm.items() if v >= NMSE_FAIR]
    words = []
    if good:
        words.append(f"the mean torque is predicted well on {', '.join(good)} (nMSE under {NMSE_GOOD:g})")
    if poor:
        words.append(f"poorly on {', '.join(poor)} (nMSE {NMSE_FAIR:g} or more)")
    words.append(uncertainty_words(cover))
    return [text, "Verdict: " + "; ".join(words) + "."]


def prediction_table(sc) -> tuple[list[Column], list[list]]:
    columns = [
        Column("joint", align="left"),
        Column("samples"),
        Column("nMSE"),
        Column("RMSE", sc.unit or "N·m"),
        Column("MAE", sc.unit or "N·m"),
        Column("inside ±2σ", "%"),
        Column("verdict", align="left"),
    ]
    rows = [
        [j, int(n), number(e), number(r), number(a), f"{100 * c:.0f}", verdict(e, c)]
        for j, n, e, r, a, c in zip(sc.channels, sc.n_samples, sc.nmse, sc.rmse, sc.mae, sc.coverage, strict=True)
    ]
    return columns, rows


PREDICTION_NOTE = (
    "Verdict: good below nMSE 0.01, fair below 0.1, poor below 1; the ±2σ band is right when it holds "
    f"{100 * COVERAGE_BAND[0]:.0f}-{100 * COVERAGE_BAND[1]:.0f} % of the measured torques (95 % expected of a "
    "calibrated predictive std), too narrow below, too wide above."
)
