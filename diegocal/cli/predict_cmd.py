"""`diegocal predict MODEL LOG`: use any fitted model on a new log.

The model's kind is recognised from the file (DESIGN.md: MODEL is any fitted output):
an ``sgp/`` directory, a calib.yaml (``pots``/``markers``/``mocap`` keys) or a pneumatic.yaml
(``chambers`` key). Each domain registers its predictor here.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated

import typer

from diegocal.cli.app import app
from diegocal.cli.common import cli_errors
from diegocal.errors import InputFileError
from diegocal.io import load_yaml


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


PREDICTORS: dict[str, Callable[[Path, Path, PredictOptions], None]] = {}


def register_predictor(kind: str, fn: Callable[[Path, Path, PredictOptions], None]) -> None:
    PREDICTORS[kind] = fn


def model_kind(path: Path) -> str:
    """'sgp', 'calib' or 'pneumatic', from the model file's shape."""
    if not path.exists():
        raise InputFileError(f"{path}: no such model file or directory")
    if path.is_dir():
        return "sgp"
    data = load_yaml(path)
    if "chambers" in data:
        return "pneumatic"
    if {"pots", "markers", "mocap"} & set(data):
        return "calib"
    raise InputFileError(f"{path}: not a fitted diegocal model (calib.yaml, pneumatic.yaml or sgp/)")


@app.command("predict")
@cli_errors
def predict(
    model: Annotated[Path, typer.Argument(help="calib.yaml, pneumatic.yaml or an sgp/ model directory.")],
    log: Annotated[Path, typer.Argument(help="Held-out log to predict.")],
    output: Annotated[Path | None, typer.Option("-o", "--output", help="Where to write the prediction.")] = None,
    sensors_from: Annotated[
        str, typer.Option("--from", help="STAC: sensor types to track from (comma list).")
    ] = "pots",
    sensors_to: Annotated[str, typer.Option("--to", help="STAC: sensor types to predict (comma list).")] = "markers",
    robot: Annotated[Path | None, typer.Option("--robot", help="Robot directory [default: the log's robot].")] = None,
    jobs: Annotated[int, typer.Option("--jobs", "-j", min=1)] = 1,
    quiet: Annotated[bool, typer.Option("--quiet", "-q")] = False,
    seed: Annotated[int, typer.Option("--seed")] = 0,
) -> None:
    """Predict a held-out log with a fitted model and report the error."""
    kind = model_kind(model)
    if kind not in PREDICTORS:
        raise InputFileError(f"{model}: predicting with a {kind} model is not available in this build")
    opts = PredictOptions(output, _split(sensors_from), _split(sensors_to), robot, jobs, quiet, seed)
    PREDICTORS[kind](model, log, opts)


def _split(text: str) -> tuple[str, ...]:
    return tuple(t.strip() for t in text.split(",") if t.strip())
