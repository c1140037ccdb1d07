"""The SGP section's tables of what a model is and how it was fitted: the model's facts, the GP
length-scales, the guard's cross-validation, the identified parameters with units and standard
errors, and a prediction log's per-joint scores. Its words and the per-joint table of how good the
model is are in :mod:`diegocal.report.sgp_text`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from diegocal.io.bundle import robot_of
from diegocal.report.layout import Column
from diegocal.sgp.store import parameters_of

#: The guard's choice per joint (cross-validation on contiguous blocks of the training log), short.
GUARD_WORDS = {
    "learnt": "GP kept as learnt",
    "released": "GP, caps released",
    "extended": "GP, stretched",
    "cut": "GP with an onset",
    "two-stage": "two stages",
    "parametric": "parametric only",
}
GUARD_NOTE = (
    "Guard: which of its candidates predicted contiguous blocks of the training log best (blocked "
    "cross-validation). 'GP kept as learnt': the GP with its maximum-likelihood hyperparameters; 'GP, caps "
    "released': length-scales stuck at their upper bound released; 'GP, stretched': the GP stretched towards its "
    "linear limit, so that it extrapolates a trend instead of reverting to zero; "
    "'GP with an onset': the GP in two sides at the onset the two stages' scan found in the joint's angle, "
    "learnt with the parametric part, offered where the cut two stages lost (off: sgp-fit --no-joint-region); "
    "'two stages': the parametric "
    "fit, then a GP on its residual (PRGP's stages), kept where it beat the other choice by one standard error; "
    "'parametric only': the GP did not beat the parametric part by one standard error and 2 % of its error and "
    "was switched off for that joint. A winner is confirmed with its hyperparameters re-learnt without the block "
    "it predicts."
)
INERTIA_ENTRIES = ("xx", "xy", "yy", "xz", "yz", "zz")  # Pinocchio's order
#: Description and unit (revolute joint, prismatic joint) of each full parameter (thesis eq. 3.30).
PARAMETER_WORDS = {
    "m": ("mass", "kg", "kg"),
    **{f"mc_{a}": (f"first moment of mass m·c, {a}", "kg·m", "kg·m") for a in "xyz"},
    **{f"I_{a}": (f"inertia about the joint frame, {a}", "kg·m²", "kg·m²") for a in INERTIA_ENTRIES},
    "fv": ("viscous friction", "N·m·s/rad", "N·s/m"),
    "fc": ("Coulomb friction", "N·m", "N"),
}
#: The baseline's friction terms (file layout 2) by the leaf layout 1 gave their parameter.
FRICTION_LEAVES = {"viscous_friction": "fv", "coulomb_friction": "fc"}
PARAMETER_NOTE = (
    "Base parameters (thesis eq. 3.30 reduced by QR with column pivoting): each is the named parameter of the "
    "link that a joint moves plus the combination of the parameters the regressor cannot tell apart from it, so a "
    "base inertia may be negative. ± SE: one posterior standard deviation; –: a parameter the log does not identify "
    "(its posterior is the prior: a joint that never moves)."
)
#: Said under the table when the model has terms diagnose added.
ADDED_NOTE = " Then the parameters of the terms diagnose added (e.g. friction confined to part of a joint's range)."


def model_kind(summary: dict) -> str:
    """pr | gp | prgp | sgp (sgp.yaml's ``kind`` is the bundle's, ``dynamics``)."""
    return summary.get("model_kind") or (summary.get("options") or {}).get("kind") or summary.get("kind", "?")


def number(v, fmt: str = ".3g") -> str:
    return "–" if v is None or not np.isfinite(v) else f"{v:{fmt}}"


def facts_rows(summary: dict, model=None) -> list[list]:
    """(quantity, value, unit) rows: what the model is and how it was fitted."""
    meta = summary.get("meta") or {}
    rows = [
        ["model kind", model_kind(summary), ""],
        ["robot", robot_of(summary)["name"], ""],
        ["fit log", Path(str(meta.get("log") or summary.get("log") or "–")).name, ""],
        ["training samples", summary.get("n_samples"), ""],
    ]
    time = getattr(model, "time_", None)
    if time is not None and len(time) > 1:
        rows.append(["training duration", f"{time[-1] - time[0]:.3g}", "s"])
    inference = summary.get("inference", "–")
    if summary.get("n_inducing"):
        inference += f", {summary['n_inducing']} inducing inputs in all"
    rows.append(["inference", inference, ""])
    if summary.get("gp_inputs"):
        rows.append(["GP inputs", ", ".join(summary["gp_inputs"]), ""])
    bound = "VFE bound on the log marginal likelihood" if summary.get("n_inducing") else "log marginal likelihood"
    rows.append([bound, f"{summary.get('log_likelihood', np.nan):.6g}", ""])
    if "converged" in summary:  # ML-II ran (absent from a model saved again without fitting)
        runs = summary.get("ml2_runs") or {}
        capped = f"no: {runs.get('stopped_at_cap', '?')} of {runs.get('runs', '?')} ML-II runs stopped at their cap"
        rows.append(["converged", "yes" if summary["converged"] else capped, ""])
    sw = (summary.get("hyperparameters") or {}).get("sigma_w")
    if sw is not None:
        rows.append(["σ_w, prior std of the parametric weights (unit-RMS columns)", f"{sw:.3g}", "N·m"])
    friction = (summary.get("options") or {}).get("friction")
    if friction:
        rows.append(["friction in the parametric part", ", ".join(friction), ""])
    rows.append(["created", str(meta.get("created") or summary.get("created") or "–"), ""])
    return rows


def slides(summary: dict) -> list[str]:
    """The model's prismatic joints, read from the units of its baseline's friction (N, N·s/m)."""
    out = []
    for t in summary.get("baseline") or ():
        units = {str(p.get("unit")) for p in (t.get("parameters") or {}).values() if isinstance(p, dict)}
        if t.get("cause") in ("viscous_friction", "coulomb_friction") and units & {"N", "N·s/m"}:
            out.append(str(t.get("channel")))
    return list(dict.fromkeys(out))


SLIDE_NOTE = "{}: a prismatic joint, its values in N, m, m/s where the headers and axes say N·m, rad, rad/s."


def lengthscale_table(summary: dict) -> tuple[list[Column], list[list], list[str]] | None:
    """GP length-scales: one row per GP input, one column per joint whose GP the guard kept."""
    hyper = summary.get("hyperparameters") or {}
    joints = [
        j
        for j in summary.get("nmse_in_sample") or {}
        if (hyper.get(j) or {}).get("lengthscales") and (hyper.get(j) or {}).get("guard_choice") != "parametric"
    ]
    if not joints:
        return None
    inputs = list(hyper[joints[0]]["lengthscales"])
    units, sliding = {"q": "rad", "qd": "rad/s", "qdd": "rad/s²"}, set(slides(summary))
    linear = {"q": "m", "qd": "m/s", "qdd": "m/s²"}

    def unit(name: str) -> str:
        kind, _, joint = name.partition(".")
        return (linear if joint in sliding else units).get(kind, "")

    columns = [Column("GP input", align="left"), Column("unit", align="left")] + [Column(j) for j in joints]
    rows = [[name, unit(name), *(number(hyper[j]["lengthscales"].get(name)) for j in joints)] for name in inputs]
    off = [j for j in summary.get("nmse_in_sample") or {} if j not in joints]
    note = (
        "Length-scale of each input in the GP of each joint (the input's unit; m and m/s for a prismatic joint): "
        "how far the input must move for the GP's correction to change; much longer than the input's range in the "
        "training log: the GP ignores that input."
    )
    if off:
        note += f" Not shown: {', '.join(off)} (GP switched off by the guard)."
    return columns, rows, [note]


def guard_table(summary: dict) -> tuple[list[Column], list[list], list[str]] | None:
    """The guard's evidence: per joint, the cross-validated nMSE of every candidate it weighed
    (``guard_validation`` in sgp.yaml), the chosen one starred; None for a model without it."""
    hyper = summary.get("hyperparameters") or {}
    joints = [j for j in summary.get("nmse_in_sample") or {} if (hyper.get(j) or {}).get("guard_validation")]
    if not joints:
        return None
    labels = [k for k in GUARD_WORDS if any(k in hyper[j]["guard_validation"] for j in joints)]
    columns = [Column("joint", align="left")] + [Column(GUARD_WORDS[k].replace(", ", ",\n")) for k in labels]
    rows = []
    for j in joints:
        weighed, chosen = hyper[j]["guard_validation"], hyper[j].get("guard_choice")
        cells = ["–" if k not in weighed else number(weighed[k]) + (" *" if k == chosen else "") for k in labels]
        rows.append([j, *cells])
    note = (
        "Cross-validated nMSE of each of the guard's candidates on contiguous blocks of the training log, each "
        "block predicted by the candidate fitted without it (* the guard's choice). The choice is not always the "
        "lowest: a GP must beat 'parametric only' by one standard error of the per-block difference and 2 % of "
        "its nMSE, two stages the other choice by one standard error; numbers on the training log's own blocks, not "
        "on new trajectories."
    )
    return columns, rows, [note]


def parameter_table(summary: dict, prismatic: frozenset = frozenset()) -> tuple[list[Column], list[list], list[str]]:
    """The identified parameters (:func:`diegocal.sgp.store.parameters_of`, either file layout): the
    base parameters and friction by joint, then the parameters of added terms, with units and SE."""
    par = parameters_of(summary)
    added = tuple(f"{t.get('cause')}:{t.get('channel')}." for t in summary.get("terms") or ())
    order = {j: i for i, j in enumerate(summary.get("joints") or [])}
    leaves = list(PARAMETER_WORDS)

    def baseline_leaf(label: str) -> tuple[str, str]:
        """(joint, leaf of PARAMETER_WORDS) of a baseline parameter, ("", "") for another."""
        cause, _, rest = label.rpartition(":")
        joint, _, leaf = rest.rpartition(".")
        leaf = FRICTION_LEAVES.get(cause, leaf if not cause else "")
        return (joint, leaf) if leaf in PARAMETER_WORDS and not label.startswith(added) else ("", "")

    def key(label: str):  # by joint, then mass, first moments, inertia, friction; added terms last
        joint, leaf = baseline_leaf(label)
        return (0, order.get(joint, len(order)), leaves.index(leaf)) if leaf else (1, 0, 0)

    rows = []
    for label in sorted(par, key=key):
        v = par[label]
        joint, leaf = baseline_leaf(label)
        if leaf:
            what, rev, pri = PARAMETER_WORDS[leaf]
            unit = v.get("unit") or (pri if joint in prismatic else rev)
        else:
            cause, _, rest = label.rpartition(":")
            channel, _, name = rest.rpartition(".")
            what, unit = f"{name}, {cause.replace('_', ' ')} on {channel}", v.get("unit") or ""
        rows.append([label, what, number(v.get("value"), "+.4g"), number(v.get("stderr"), ".2g"), unit])
    columns = [
        Column("parameter", align="left"),
        Column("what it is", align="left"),
        Column("value"),
        Column("± SE"),
        Column("unit", align="left"),
    ]
    return columns, rows, [PARAMETER_NOTE + (ADDED_NOTE if added else "")]
