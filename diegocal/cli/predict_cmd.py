"""`diegocal predict MODEL LOG`: use any fitted model on a new log.

The model's kind is read from its bundle header by the one loader, :func:`diegocal.io.bundle.load_bundle`
(DESIGN.md: MODEL is any fitted output; STYLE.md: dispatch on the kind, never on file names). A
diagnosis.yaml stands for the extended model it names. Each domain registers its predictor here.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated

import typer

from diegocal.cli.app import app
from diegocal.cli.choices import SENSOR_TYPES
from diegocal.cli.common import cli_errors, comma_list, command_line, log_output, split_words
from diegocal.domains import domain
from diegocal.errors import InputFileError


@dataclass(frozen=True)
class PredictOptions:
    """Options of `predict`, parsed once; each predictor reads the ones it needs."""

    output: Path | None
    sensors_from: tuple[str, ...]  # STAC: which sensor types drive the q-phase
    sensors_to: tuple[str, ...]  # STAC: which sensor types are predicted
    robot: Path | None
    jobs: int
    quiet: bool
    seed: int
    source: dict | None = None  # what made the prediction log (Log.source): command, model, log, created


PREDICTORS: dict[str, Callable[[Path, Path, PredictOptions], None]] = {}


def register_predictor(kind: str, fn: Callable[[Path, Path, PredictOptions], None]) -> None:
    PREDICTORS[kind] = fn


def resolve_model(path: Path) -> tuple[str, Path]:
    """(domain, model path) of a fitted output; a diagnosis.yaml resolves to the extended model it
    names (beside it)."""
    from diegocal.io.bundle import load_bundle

    bundle = load_bundle(path)
    if bundle.kind == "diagnosis":
        name = bundle.data.get("extended_model")
        if not name:
            raise InputFileError(f"{path}: this diagnosis names no extended model")
        return resolve_model(path.parent / str(name))
    return domain(bundle.kind).name, path


def model_domain(path: Path) -> str:
    """The domain of the model at ``path`` (its bundle kind), whose predictor reads it."""
    return resolve_model(path)[0]


@app.command("predict")
@cli_errors
def predict(
    model: Annotated[
        Path,
        typer.Argument(help="Any fitted model: calib.yaml, pneumatic.yaml, an sgp/ directory, or a diagnosis.yaml."),
    ],
    log: Annotated[Path, typer.Argument(help="Held-out log to predict (.h5 or .csv).")],
    output: Annotated[
        Path | None,
        typer.Option(
            "-o",
            "--output",
            callback=log_output,
            help="Log to write the prediction to (.h5 or .csv); by default LOG.prediction.h5 beside the log.",
        ),
    ] = None,
    sensors_from: Annotated[
        str,
        typer.Option(
            "--from",
            callback=comma_list(SENSOR_TYPES),
            help="STAC models: the sensor types to track the joint angles from, comma-separated "
            f"({', '.join(SENSOR_TYPES)}; pots is every pot).",
        ),
    ] = "pots",
    sensors_to: Annotated[
        str,
        typer.Option(
            "--to",
            callback=comma_list(SENSOR_TYPES),
            help="STAC models: the sensor types to predict, comma-separated.",
        ),
    ] = "markers",
    robot: Annotated[
        Path | None,
        typer.Option(
            "--robot",
            help="Robot directory or URDF file; by default the log's robot, else the model's.",
        ),
    ] = None,
    jobs: Annotated[
        int, typer.Option("--jobs", "-j", min=1, help="Threads for the joint-angle tracking of STAC models.")
    ] = 1,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No summary table.")] = False,
    seed: Annotated[int, typer.Option("--seed", help="Random seed (the predictions are deterministic).")] = 0,
) -> None:
    """Predict a held-out log with a fitted model and report the error (the model file is only read)."""
    kind, model = resolve_model(model)
    if robot is None:
        check_log_robot(model, log)
    if kind not in PREDICTORS:
        raise InputFileError(f"{model}: predicting with a {kind} model is not available in this build")
    from datetime import UTC, datetime

    source = {
        "command": command_line("diegocal predict"),
        "model": str(model.resolve()),
        "log": str(log.resolve()),
        "created": datetime.now(UTC).isoformat(timespec="seconds"),
    }
    opts = PredictOptions(output, split_words(sensors_from), split_words(sensors_to), robot, jobs, quiet, seed, source)
    PREDICTORS[kind](model, log, opts)


def check_log_robot(model: Path, log: Path) -> None:
    """Refuse (one line) a log that names a robot whose robot.urdf/sensors.yaml differ from those
    the model was fitted on (the hash in the model's header; DESIGN.md "Command line")."""
    from diegocal.errors import RobotConfigError
    from diegocal.io.bundle import load_bundle, same_robot
    from diegocal.io.files import log_robot
    from diegocal.robot import resolve_robot_dir

    record = load_bundle(model).robot
    name = log_robot(log)
    if not name or not record.get("hash"):
        return
    try:
        source = resolve_robot_dir(None, name)
    except RobotConfigError:
        return  # a robot the log names but that is not here: the predictor decides
    if not same_robot(record, source):
        raise RobotConfigError(
            f"{log} is a log of robot {name} ({source}), but {model} was fitted on {record.get('name')} "
            f"({record.get('dir')}): their robot.urdf or sensors.yaml differ"
        )
