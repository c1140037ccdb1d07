"""Predict a log with any fitted model: one door for every kind of bundle (STYLE.md, "One door").

::

    from diegocal.predict import predict, PredictOptions
    result = predict("run.calib.yaml", "held.h5", PredictOptions(sources=("pots",), targets=("markers",)))
    result.log        # the prediction as a Log (q, pots, markers | tau, tau_std | pressure)
    result.rows       # what was predicted and how well, (label, value, ...) rows
    result.warnings   # sentences: the log does not look like the model's session, ...

The model's domain is read from its bundle header (:func:`diegocal.io.bundle.load_bundle`); a
diagnosis.yaml stands for the extended model it names. The model file is only read.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from diegocal.domains import domain as domain_record
from diegocal.errors import InputFileError, RobotConfigError
from diegocal.io import Log, load_log, make_stream
from diegocal.io.bundle import load_bundle, same_robot
from diegocal.io.files import log_robot

#: A prediction this many times a calibration's own noise is no prediction of the session it was
#: fitted on.
IMPLAUSIBLE = 20.0


@dataclass(frozen=True)
class PredictOptions:
    """Options of :func:`predict`; each domain reads the ones it needs.

    sources, targets : kinematics: the sensor types the joint angles are tracked from, and those
        predicted (:data:`diegocal.stac.predict.SOURCE_TYPES`)
    robot : a robot directory or URDF to use instead of the log's or the model's
    jobs : kinematics: threads of the joint-angle tracking
    seed : the predictions are deterministic; recorded for the record
    source : what made the prediction (command, model, log, created), stored in the written log
    progress : kinematics: callable(text) told how far the joint-angle tracking is (None: silent)
    """

    sources: tuple[str, ...] = ("pots",)
    targets: tuple[str, ...] = ("markers",)
    robot: Path | None = None
    jobs: int = 1
    seed: int = 0
    source: dict | None = None
    progress: Callable[[str], None] | None = None


@dataclass(frozen=True)
class Prediction:
    """What :func:`predict` returns: the predicted streams as a log on the input's clock, and the
    summary of how well they match (``title``, ``columns``, ``rows``) with ``warnings`` in words."""

    domain: str
    model: Path
    log: Log
    title: str
    rows: list
    columns: tuple = ("quantity", "value")
    warnings: tuple[str, ...] = field(default=())


def resolve_model(path) -> tuple[str, Path]:
    """(domain, model path) of a fitted output; a diagnosis.yaml resolves to the extended model it
    names (beside it)."""
    path = Path(path)
    bundle = load_bundle(path)
    if bundle.kind == "diagnosis":
        name = bundle.data.get("extended_model")
        if not name:
            raise InputFileError(f"{path}: this diagnosis names no extended model")
        return resolve_model(path.parent / str(name))
    return domain_record(bundle.kind).name, path


def check_log_robot(model: Path, log_path: Path) -> None:
    """Refuse (one line) a log that names a robot whose robot.urdf/sensors.yaml differ from those
    the model was fitted on (the hash in the model's header; DESIGN.md "Command line")."""
    from diegocal.robot import resolve_robot_dir

    record = load_bundle(model).robot
    name = log_robot(log_path)
    if not name or not record.get("hash"):
        return
    try:
        source = resolve_robot_dir(None, name)
    except RobotConfigError:
        return  # a robot the log names but that is not here: the predictor decides
    if not same_robot(record, source):
        raise RobotConfigError(
            f"{log_path} is a log of robot {name} ({source}), but {model} was fitted on {record.get('name')} "
            f"({record.get('dir')}): their robot.urdf or sensors.yaml differ (--robot DIR names the robot to use)"
        )


def predict(model, log, options: PredictOptions | None = None) -> Prediction:
    """Predict ``log`` (a Log or a path) with the fitted model at ``model`` (any bundle, or a
    diagnosis.yaml for its extended model). Never writes; never reads the log's ``/truth``."""
    options = options or PredictOptions()
    domain, path = resolve_model(model)
    if isinstance(log, (str, Path)):
        if options.robot is None:
            check_log_robot(path, Path(log))
        log = load_log(log)
    log = log.without_truth()
    return PREDICTORS[domain](path, log, options)


# ----------------------------------------------------------------------------- kinematics
def _kinematics(path: Path, log: Log, options: PredictOptions) -> Prediction:
    """Cross-sensor prediction with a calibration (thesis §2.7.2, Tables 2.1-2.2)."""
    from diegocal.robot.resolve import robot_for_model
    from diegocal.stac.calibration import READING_UNITS, Calibration
    from diegocal.stac.predict import predict as stac_predict
    from diegocal.stac.result import StacOptions

    bundle = load_bundle(path)
    cal = Calibration.from_dict(bundle.data, source=str(path))
    robot = robot_for_model(bundle.robot, options.robot, log, path)
    pred = stac_predict(log, robot, cal, options.sources, options.targets,
                        StacOptions(jobs=options.jobs, seed=options.seed), progress=options.progress)
    streams = {"q": make_stream(robot.joint_names, pred.q)}
    if pred.pot_names:
        streams["pots"] = make_stream(pred.pot_names, pred.pots)
    if pred.marker_names:
        streams["markers"] = make_stream(pred.marker_names, pred.markers)
    warnings = []
    for target, mae in pred.mae.items():
        sigma = cal.sigma_by_group.get(target, cal.sigma_markers if target == "markers" else cal.sigma_pots)
        if np.isfinite(sigma) and sigma > 0 and mae > IMPLAUSIBLE * sigma:
            unit = f" {READING_UNITS[target]}" if target in READING_UNITS else ""
            warnings.append(
                f"{target} MAE {mae:.4g}{unit} is {mae / sigma:.0f} times the calibration's own noise "
                f"({sigma:.3g}{unit}): this log does not look like the session {path.name} was fitted on "
                "(another robot, mocap frame or marker placement?); hold out part of the same session: "
                "diegocal split LOG --at 0.8 -o TRAIN HELDOUT"
            )
    rows = [(f"{t} ({READING_UNITS.get(t, 'sensor unit')})", pred.mae[t]) for t in pred.targets]
    asked = "+".join(options.sources)
    used = "+".join(pred.sources)
    sources = asked if set(options.sources) == set(pred.sources) else f"{asked} ({used})"
    title = f"cross-sensor prediction MAE from {sources} (thesis Tables 2.1-2.2)"
    out = Log(log.time, streams, robot=log.robot, rate_hz=log.rate_hz, source=options.source)
    return Prediction("kinematics", path, out, title, rows, warnings=tuple(warnings))


# ----------------------------------------------------------------------------- dynamics
def _dynamics(path: Path, log: Log, options: PredictOptions) -> Prediction:
    """Torques and their predictive std with a dynamics model (thesis eq. 3.8, 3.20)."""
    from diegocal.evaluate import score
    from diegocal.robot import data_joints, load_robot, resolve_robot_dir
    from diegocal.sgp.model import log_arrays
    from diegocal.sgp.store import load_model
    from diegocal.sgp.streams import without_clipped

    # the log's joints, as the fit took them (a gripper's joints that have a torque stream)
    robot = load_robot(resolve_robot_dir(options.robot, log.robot), joints=data_joints(log)) if options.robot else None
    model = load_model(path, robot=robot)
    pred = model.predict(log)
    names = model.joint_names  # the joints with a fitted torque
    q, qd, qdd = log_arrays(log, model.robot, need_tau=False)
    every = model.robot.joint_names
    streams = {
        "q": make_stream(every, q),
        "qd": make_stream(every, qd),
        "qdd": make_stream(every, qdd),
        "tau": make_stream(names, pred.tau),
        "tau_std": make_stream(names, pred.tau_std),
    }
    rows = [("model", model.options.kind), ("samples", log.n_samples)]
    for term in model.fitted_terms():  # extra terms (diagnose's extended model), with their values
        values = ", ".join(f"{p.name}={p.value:.4g} {p.unit}".rstrip() for p in term.parameters)
        rows.append((f"term {term.label}", values))
    warnings = ()
    if log.has("tau"):
        measured = log.stream("tau").select(names).data
        streams["tau_measured"] = make_stream(names, measured)
        sc = score(without_clipped(measured, names), pred.tau, names, std=pred.tau_std)  # clipped: not scored
        rows += [(f"nMSE {j}", float(e)) for j, e in zip(names, sc.nmse, strict=True)]
        rows += [(f"RMSE {j}", float(e)) for j, e in zip(names, sc.rmse, strict=True)]  # diagnose's measure
        rows += [(f"within ±2σ {j}", float(c)) for j, c in zip(names, sc.coverage, strict=True)]
        warnings = coverage_warnings(names, sc.coverage)
    out = Log(log.time, streams, robot=log.robot, rate_hz=log.rate_hz, source=options.source)
    return Prediction("dynamics", path, out, "predict torques", rows, warnings=warnings)


def coverage_warnings(names, coverage) -> tuple[str, ...]:
    """A sentence naming the joints whose measured torques fall within ±2σ of the prediction less
    or more often than :data:`diegocal.evaluate.COVERAGE_BAND`: the model's uncertainty is then
    not to be taken at its word on this log."""
    from diegocal.evaluate import COVERAGE_BAND

    lo, hi = COVERAGE_BAND
    low = [f"{j} {c:.3f}" for j, c in zip(names, coverage, strict=True) if c < lo]
    high = [f"{j} {c:.3f}" for j, c in zip(names, coverage, strict=True) if c > hi]
    parts = []
    if low:
        why = "states the training log did not constrain, a drifted robot, or noise that is not white"
        parts.append(f"below {lo} on {', '.join(low)}: the predictive std understates the error ({why})")
    if high:
        parts.append(f"above {hi} on {', '.join(high)}: the predictive std overstates the error")
    if not parts:
        return ()
    hint = "; `diegocal diagnose` on the training log names effects the model lacks" if low else ""
    return ("fraction of measured torques within ±2σ (0.95 if calibrated) " + "; ".join(parts) + hint,)


# ----------------------------------------------------------------------------- pneumatics
def _pneumatics(path: Path, log: Log, options: PredictOptions) -> Prediction:
    """Open-loop pressure from u, v, vdot (§4.5.4), reset every 2 s, and the 2-s drift per chamber
    (Fig. 4.13's figure of merit)."""
    from diegocal.pneumatic.data import extract
    from diegocal.pneumatic.files import load_model
    from diegocal.pneumatic.predict import drift, predict_with_resets

    model = load_model(path)
    pred, rows, drifts = {}, [], []
    for name, ch in model.chambers.items():
        data = extract(log, name, ch.volume_sensor, ch.params.supply, ch.params.room, check_span=False)
        pred[name] = predict_with_resets(ch.params, data)
        d = drift(ch.params, data)
        drifts.append(d.final)
        rows.append((name, f"{ch.raw.get('drift_2s', float('nan')):.1%}", f"{d.final:.1%}"))
    names = list(pred)
    drifts = np.array(drifts)
    if len(rows) > 12:
        rows = sorted(rows, key=lambda r: -float(r[2].rstrip("%")))[:10]
        rows.append(("...", "", ""))
    rows += [
        ("median / max", "", f"{np.median(drifts):.1%} / {drifts.max():.1%}"),
        ("< 4% / < 10% of chambers", "", f"{(drifts < 0.04).sum()} / {(drifts < 0.10).sum()} of {drifts.size}"),
    ]
    streams = {"pressure": make_stream(names, np.column_stack([pred[n] for n in names]))}
    out = Log(log.time, streams, robot=log.robot, rate_hz=log.rate_hz, source=options.source)
    title = "predict pneumatic: RMS error 2 s after the last measurement, fraction of Pc - Pr"
    return Prediction("pneumatics", path, out, title, rows, ("chamber", "fit log", "this log"))


#: Domain -> its predictor.
PREDICTORS = {"kinematics": _kinematics, "dynamics": _dynamics, "pneumatics": _pneumatics}
