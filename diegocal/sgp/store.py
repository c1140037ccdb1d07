"""Saving and loading fitted dynamics models: an ``sgp/`` directory (DESIGN.md).

Layout::

    sgp.yaml        summary: kind, joints, options, hyperparameters, the fitted parameters as the
                    terms of the dynamics baseline (``baseline``: the rigid body's base parameters,
                    a viscous and a Coulomb friction term per joint, each ``{value, stderr, unit}``)
                    and the added terms (``terms``), in-sample nMSE per joint, meta {log, robot,
                    command, created}. Layout 1 (no ``layout`` key) wrote the base parameters as
                    ``parameters: {name: {value, std}}``; :func:`parameters_of` reads both.
    model.npz       training set (u, tau; time with a torque_lag term), base-parameter map, packed
                    hyperparameters, inducing inputs: enough to rebuild the posterior exactly
                    without optimising

A model with extra terms (``diagnose``'s extended model, :mod:`diegocal.sgp.terms`) lists them in
sgp.yaml under ``terms`` (``{cause, channel, region, parameters, extra}``); a file without
``terms`` is a model without extra terms (files written before terms existed load unchanged).
``save_model(..., header=)`` writes a bundle header (:mod:`diegocal.io.bundle`) at the top level;
the model's own kind (pr, sgp, ...) then stays under ``options.kind`` and ``model_kind``.
    robot/          copy of the robot's URDF and sensors.yaml, so the model is self-contained

Files are written atomically (:func:`diegocal.io.atomic_path`, :func:`diegocal.io.save_yaml`).
(``np.savez``/``np.load`` of the arrays live here rather than in ``diegocal.io``, which has no
array-bundle helper yet.)
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from diegocal.errors import InputFileError
from diegocal.io import atomic_path, load_yaml, save_yaml
from diegocal.io.bundle import LAYOUT, save_robot_copy
from diegocal.robot import load_robot
from diegocal.sgp.gp import Hyperparameters, per_output
from diegocal.sgp.guard_options import Stages
from diegocal.sgp.model import DynamicsModel, SGPOptions
from diegocal.sgp.terms import FRICTION_CAUSE, is_filter
from diegocal.terms import correlated_pairs, make_term, read_parameter, term_from_dict, write_correlated

FORMAT = "diegocal-sgp"
VERSION = 1


def _pack_hyper(prefix: str, hp: Hyperparameters | None, inducing, out: dict) -> None:
    """Packed hyperparameters and, per output j with inducing inputs, ``{prefix}_inducing_{j}``."""
    if hp is None:
        return
    out[f"{prefix}_vec"] = hp.pack()
    out[f"{prefix}_sizes"] = np.array([t.size for t in hp.theta], dtype=int)
    if inducing is not None:
        for j, Z in enumerate(per_output(inducing, len(hp.theta))):
            if Z is not None:
                out[f"{prefix}_inducing_{j}"] = Z


def _unpack_hyper(prefix: str, arrays) -> tuple[Hyperparameters | None, list | np.ndarray | None]:
    """(hyperparameters, inducing inputs per output (None: exact) or None); a file of an older
    version holds one array ``{prefix}_inducing`` shared by every output."""
    if f"{prefix}_vec" not in arrays:
        return None, None
    sizes = list(arrays[f"{prefix}_sizes"])
    hp = Hyperparameters.unpack(arrays[f"{prefix}_vec"], sizes)
    if f"{prefix}_inducing" in arrays:
        return hp, arrays[f"{prefix}_inducing"]
    ind = [arrays.get(f"{prefix}_inducing_{j}") for j in range(len(sizes))]
    return hp, (ind if any(z is not None for z in ind) else None)


def ml2_unconverged(runs: int, capped: int, cap) -> str:
    """In words: ``capped`` of ``runs`` ML-II runs stopped at their iteration cap ``cap``."""
    return (
        f"ML-II: {capped} of {runs} hyperparameter runs stopped at their iteration cap ({cap}) before their tolerance"
    )


def unconverged(summary: dict) -> str | None:
    """In words, why a fit (its sgp.yaml ``summary``) did not converge; None when it did."""
    if summary.get("converged", True):
        return None
    runs = summary.get("ml2_runs") or {}
    cap = (summary.get("options") or {}).get("maxiter", "?")
    return ml2_unconverged(runs.get("runs", "?"), runs.get("stopped_at_cap", "?"), cap)


def summary_dict(model, meta: dict | None = None) -> dict:
    """The content of sgp.yaml."""
    par = model.parametric_
    est = model.gp_
    out = {
        "format": FORMAT,
        "version": VERSION,
        "kind": model.options.kind,
        "robot": model.robot.name,
        "joints": list(model.joint_names),
        "joints_without_tau": list(model.joints_without_tau),
        "n_samples": int(len(model.U_)),
        "inference": est.inference,
        "n_inducing": None if est.inducing_ is None else int(sum(len(z) for z in est.inducing_ if z is not None)),
        "gp_inputs": [model.input_names[d] for d in model.gp_dims] if model.options.kind != "pr" else [],
        "log_likelihood": float(est.log_likelihood_),
        "nmse_in_sample": {j: float(v) for j, v in zip(model.joint_names, model.nmse_in_sample_, strict=True)},
        "hyperparameters": model.hyperparameters_,
        "layout": LAYOUT,
        "baseline": None if par is None else _baseline_dicts(model),
        "options": model.options.to_dict(),
        "meta": dict(meta or {}),
    }
    if model.converged_ is not None:  # ML-II ran: every L-BFGS-B run (starts, the guard's refits
        # and stages, PRGP's PR stage) at its tolerance, or how many its iteration cap stopped
        out["converged"] = model.converged_
        out["ml2_runs"] = dict(zip(("runs", "stopped_at_cap"), model.ml2_runs_, strict=True))
    terms = getattr(model, "terms", ())
    if terms:
        out["terms"] = [t.to_dict() for t in model.fitted_terms()]
    return out


#: The unit of a rigid-body parameter by its leaf name (Pinocchio's order; base parameters carry
#: the unit of the parameter they are named after).
INERTIAL_UNITS = {"m": "kg", "mc": "kg·m", "I": "kg·m²"}
#: Friction units on a prismatic joint (a force): viscous, Coulomb.
PRISMATIC_FRICTION_UNITS = {"viscous": "N·s/m", "coulomb": "N"}
#: Layout 1's friction column tags.
_LEGACY_FRICTION = {"fv": "viscous", "fc": "coulomb"}


def _baseline_dicts(model) -> list[dict]:
    """:func:`baseline_terms` as sgp.yaml writes them, with the base parameters that trade off
    (``correlated``, as calib.yaml writes STAC's)."""
    par, n = model.parametric_, model.base_.n_base
    labels = []
    for name in par.names[:n]:
        kind, joint = _friction_of(name)
        labels.append(f"{model.robot.name}.{name}" if kind is None else f"{joint}.{kind}")
    out = [t.to_dict() for t in baseline_terms(model)]
    write_correlated(out, correlated_pairs(np.asarray(par.cov, float)[:n, :n], labels))
    return out


#: A base parameter whose posterior variance is this share of its prior's or more is not
#: identified by the data (:attr:`~diegocal.sgp.model.DynamicsModel.prior_share_`): written null
PRIOR_ONLY = 0.99
#: ... and one whose share is over this is held by the prior more than by the data (a warning)
PRIOR_HELD = 0.5


def prior_held(model) -> tuple[list[str], list[str]]:
    """(names of the base parameters the data do not identify, names of those the prior holds
    more than the data do): :data:`PRIOR_ONLY`, :data:`PRIOR_HELD`."""
    share, par = model.prior_share_, model.parametric_
    if share is None or par is None:
        return [], []
    n = model.base_.n_base
    names = par.names[:n]
    return (
        [a for a, s in zip(names, share[:n], strict=True) if s > PRIOR_ONLY],
        [a for a, s in zip(names, share[:n], strict=True) if PRIOR_HELD < s <= PRIOR_ONLY],
    )


def baseline_terms(model) -> list:
    """The fitted baseline as terms: one ``rigid_body`` term with the base parameters (named after
    the parameter each is led by, ``joint2.I_zz``, in its unit) and a ``viscous_friction`` and
    ``coulomb_friction`` term per joint (:mod:`diegocal.causes`), values and standard errors of the
    posterior (thesis eq. 3.25)."""
    par = model.parametric_
    prismatic = model.robot.prismatic_joints
    rigid, friction = {}, {}
    n_base = model.base_.n_base
    values, stderr = par.values[:n_base].copy(), par.stderr[:n_base].copy()
    share = model.prior_share_
    if share is not None:  # the data say nothing of it: no value (null), not the prior's 0 ± σ_w
        prior_only = share[:n_base] > PRIOR_ONLY
        values[prior_only] = stderr[prior_only] = np.nan
    for name, v, se in zip(par.names[:n_base], values, stderr, strict=True):
        kind, joint = _friction_of(name)
        if kind is None:
            leaf = name.rpartition(".")[2]
            rigid[name] = (float(v), float(se), INERTIAL_UNITS[leaf.split("_")[0]])
        else:
            friction[(kind, joint)] = (float(v), float(se))
    out = []
    if rigid:
        t = make_term("rigid_body", model.robot.name, {k: v[0] for k, v in rigid.items()},
                      stderr={k: v[1] for k, v in rigid.items()})
        out.append(replace(t, parameters=tuple(replace(p, unit=rigid[p.name][2]) for p in t.parameters)))
    for kind in ("viscous", "coulomb"):
        for joint in model.robot.joint_names:
            if (kind, joint) not in friction:
                continue
            v, se = friction[(kind, joint)]
            t = make_term(FRICTION_CAUSE[kind], joint, [v], stderr=[se])
            if joint in prismatic:
                t = replace(t, parameters=(replace(t.parameters[0], unit=PRISMATIC_FRICTION_UNITS[kind]),))
            out.append(t)
    return out


def _friction_of(name: str) -> tuple[str | None, str | None]:
    """(kind, joint) of a friction column's name (``coulomb_friction:j.coulomb``, layout 1's ``j.fc``)."""
    if ":" in name:
        cause, _, rest = name.partition(":")
        kind = next((k for k, c in FRICTION_CAUSE.items() if c == cause), None)
        return (kind, rest.rpartition(".")[0]) if kind else (None, None)
    joint, _, leaf = name.rpartition(".")
    kind = _LEGACY_FRICTION.get(leaf)
    return (kind, joint) if kind else (None, None)


def parameters_of(summary: dict) -> dict:
    """Every fitted parameter of an sgp.yaml, ``label -> {value, stderr, unit}``: the baseline's
    (layout 2: ``rigid_body`` parameters by name, friction as ``viscous_friction:joint1.viscous``;
    layout 1: ``parameters`` as written, ``std`` read as the standard error), then the added terms'."""
    out = {}
    if "baseline" in summary:
        for d in summary.get("baseline") or ():
            t = term_from_dict(d, "sgp.yaml baseline", "dynamics")
            for p in t.parameters:
                label = p.name if t.cause == "rigid_body" else f"{t.cause}:{t.channel}.{p.name}"
                out[label] = p.to_dict()
    else:
        for name, d in (summary.get("parameters") or {}).items():
            out[name] = read_parameter(name, d).to_dict()
    for d in summary.get("terms") or ():
        t = term_from_dict(d, "sgp.yaml terms", "dynamics")
        for p in t.parameters:
            out[f"{t.cause}:{t.channel}.{p.name}"] = p.to_dict()
    return out


def save_model(model, directory, meta: dict | None = None, header: dict | None = None) -> Path:
    """Write ``directory/`` (sgp.yaml, model.npz, robot/); returns the directory. ``header``
    (a bundle header, kind ``dynamics``) is merged at the top level of sgp.yaml."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    st = model.state()
    arrays = {"u": model.U_, "tau": model.tau_}
    if getattr(model, "time_", None) is not None:
        arrays["time"] = model.time_
    arrays.update({f"base_{k}": np.asarray(v) for k, v in st["base"].items()})
    _pack_hyper("hyper", st["hyper"], st["inducing"], arrays)
    _pack_hyper("hyper_pr", st.get("hyper_pr"), st.get("inducing_pr"), arrays)
    stages = st.get("stages")
    if stages is not None:  # the guard's two stages: PR, the GPs on its residual, the choice
        arrays["stage_selection"] = np.array(stages.selection, dtype=str)
        _pack_hyper("stage_pr", stages.pr, None, arrays)
        _pack_hyper("stage_res", stages.residual, st.get("inducing_res"), arrays)
    with atomic_path(directory / "model.npz") as tmp, open(tmp, "wb") as fh:
        np.savez(fh, **arrays)
    robot = model.robot
    if robot.source is not None:  # with its locked joints, so the copy rebuilds the same model
        save_robot_copy(robot, directory / "robot")
    summary = summary_dict(model, meta)
    if header:  # the header's keys (kind: dynamics, robot: {name, dir, hash}, ...) win
        merged = {**dict(header), "model_kind": summary["kind"]}
        merged.update({k: v for k, v in summary.items() if k not in header})
        summary = merged
    save_yaml(summary, directory / "sgp.yaml")
    return directory


def is_model_dir(path) -> bool:
    path = Path(path)
    return path.is_dir() and (path / "sgp.yaml").is_file()


def load_summary(directory) -> dict:
    directory = Path(directory)
    if not is_model_dir(directory):
        raise InputFileError(f"{directory}: not an sgp model directory (no sgp.yaml)")
    data = load_yaml(directory / "sgp.yaml")
    if data.get("format") != FORMAT:
        raise InputFileError(f"{directory}/sgp.yaml: format is {data.get('format')!r}, expected {FORMAT!r}")
    return data


def _unidentified(model) -> tuple:
    """The model's columns whose saved value is null: not identified when it was fitted."""
    out, at = [], model.base_.n_base
    for t in model.terms:
        if not is_filter(t):
            out += [at + i for i, p in enumerate(t.linear) if not np.isfinite(p.value)]
            at += len(t.linear)
    return tuple(out)


def load_model(directory, robot=None):
    """Rebuild a saved model: same predictions as the one saved (no optimisation is rerun).

    ``robot`` (a Robot) overrides the copy stored in ``directory/robot``.
    """
    directory = Path(directory)
    summary = load_summary(directory)
    npz = directory / "model.npz"
    if not npz.is_file():
        raise InputFileError(f"{directory}: no model.npz")
    try:
        with np.load(npz, allow_pickle=False) as f:
            arrays = {k: f[k] for k in f.files}
    except (OSError, ValueError) as exc:
        raise InputFileError(f"{npz}: cannot read ({exc})") from None
    if robot is None:  # the copy, with every joint the model was fitted with (a gripper's too)
        fitted = [*(summary.get("joints") or []), *(summary.get("joints_without_tau") or [])]
        robot = load_robot(directory / "robot", joints=fitted)
    options = SGPOptions.from_dict(summary["options"])
    terms = [term_from_dict(t, f"{directory}/sgp.yaml terms", "dynamics") for t in summary.get("terms") or ()]
    model = DynamicsModel(robot, options, tau_joints=summary.get("joints"), terms=terms)
    n = robot.n_joints
    u = arrays["u"]
    q, qd, qdd = u[:, :n], u[:, n : 2 * n], u[:, 2 * n :]
    hyper, inducing = _unpack_hyper("hyper", arrays)
    hyper_pr, inducing_pr = _unpack_hyper("hyper_pr", arrays)
    base = {k[5:]: arrays[k] for k in arrays if k.startswith("base_")}
    state = {
        "base": base,
        "hyper": hyper,
        "inducing": inducing,
        "hyper_pr": hyper_pr,
        "inducing_pr": inducing_pr,
    }
    if "stage_selection" in arrays:  # a file without it predicts every joint by the joint posterior
        stage_res, state["inducing_res"] = _unpack_hyper("stage_res", arrays)
        selection = tuple(str(c) for c in arrays["stage_selection"])
        state["stages"] = Stages(selection, _unpack_hyper("stage_pr", arrays)[0], stage_res)
    model.fit_arrays(q, qd, qdd, arrays["tau"], state=state, time=arrays.get("time"))
    model.unidentified_ = _unidentified(model)
    hp = summary.get("hyperparameters") or {}
    choices = [(hp.get(j) or {}).get("guard_choice") for j in model.joint_names]
    if all(choices):  # the guard's cross-validated choice and scores, as fitted (reporting only)
        model.gp_.selection_ = tuple(choices)
        weighed = [(hp.get(j) or {}).get("guard_validation") for j in model.joint_names]
        if all(isinstance(w, dict) and w for w in weighed):  # an edited file's odd entry is left out
            try:
                labels = dict.fromkeys(k for w in weighed for k in w)  # "cut" only where it cut
                scores = {k: np.array([float(w.get(k, np.nan)) for w in weighed]) for k in labels}
            except (TypeError, ValueError):
                scores = None
            if scores is not None:
                model.gp_.validation_scores_ = scores
    return model


def region_text(entry: dict) -> str:
    """", cut at q.joint3 ≥ 1.78 rad" for a joint whose two-stage GP is cut at an onset in its
    angle (sgp.yaml ``hyperparameters.<joint>.region``), else ""."""
    region = entry.get("region")
    if not isinstance(region, dict) or not isinstance(region.get("onset"), (int, float)):
        return ""
    return f", cut at {region.get('input', 'its angle')} ≥ {region['onset']:.3g} rad"
