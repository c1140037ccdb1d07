"""`diegocal predict MODEL LOG`: use any fitted model on a new log (:func:`diegocal.predict.predict`,
which dispatches on the model's bundle kind; a diagnosis.yaml stands for its extended model)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer
from rich.markup import escape

from diegocal.cli.app import app
from diegocal.cli.choices import SENSOR_TYPES, SOURCE_TYPES
from diegocal.cli.common import (
    cli_errors,
    comma_list,
    command_line,
    default_output,
    distinct_output,
    errors,
    log_output,
    split_words,
    summary,
    warn,
)

if TYPE_CHECKING:
    from diegocal.predict import Prediction


@dataclass(frozen=True)
class PredictArgs:
    """`diegocal predict`'s options, parsed once: the command's parameters by name (``ctx.params``)."""

    model: Path
    log: Path
    output: Path | None
    sensors_from: str
    sensors_to: str
    robot: str | None
    jobs: int
    quiet: bool
    seed: int

    def __post_init__(self):
        distinct_output((self.out,), (self.model, self.log, self.robot))

    @property
    def out(self) -> Path:
        """The prediction log: ``-o``, by default LOG.prediction.h5 beside the log."""
        return self.output or default_output(self.log, ".prediction.h5")


def run_predict(args: PredictArgs, command: str = "diegocal predict", progress=None) -> Prediction:
    """Predict the log with the model (:func:`diegocal.predict.predict`) and write the prediction
    log. Raises DiegocalError; prints nothing (``progress(text)``: how far a long tracking is)."""
    # the library is imported when the command runs, so that `--help` answers at once
    from datetime import UTC, datetime

    from diegocal.io import save_log
    from diegocal.predict import PredictOptions, predict

    source = {
        "command": command,
        "model": str(args.model.resolve()),
        "log": str(args.log.resolve()),
        "created": datetime.now(UTC).isoformat(timespec="seconds"),
    }
    options = PredictOptions(
        split_words(args.sensors_from), split_words(args.sensors_to), args.robot, args.jobs, args.seed, source,
        progress,
    )
    result = predict(args.model, args.log, options)
    save_log(result.log, args.out)
    return result


@app.command("predict")
@cli_errors
def predict(
    ctx: typer.Context,
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
            callback=comma_list(SOURCE_TYPES),
            help="STAC models: the sensor types to track the joint angles from, comma-separated "
            f"({', '.join(SENSOR_TYPES)}; pots is every pot), or others: each reading predicted from every "
            "other sensor of its frame (what diagnose scores).",
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
        str | None,
        typer.Option(
            "--robot",
            help="Robot directory or URDF file; by default the log's robot, else the model's.",
        ),
    ] = None,
    jobs: Annotated[
        int, typer.Option("--jobs", "-j", min=1, help="Threads for the joint-angle tracking of STAC models.")
    ] = 1,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No progress and no summary table.")] = False,
    seed: Annotated[
        int,
        typer.Option(
            "--seed",
            help="Recorded in the prediction's header; the predictions do not depend on it (scripts may pass "
            "one --seed to every command).",
        ),
    ] = 0,
) -> None:
    """Predict a held-out log with a fitted model and report the error (the model file is only read)."""
    args = PredictArgs(**ctx.params)

    def progress(text: str) -> None:
        errors.print(f"[dim]predict:[/] {escape(text)}", highlight=False)

    result = run_predict(args, command_line("diegocal predict"), None if args.quiet else progress)
    for text in result.warnings:
        warn(text)
    written = ("prediction", *([""] * (len(result.columns) - 2)), str(args.out))
    summary(result.title, [*result.rows, written], columns=result.columns, quiet=args.quiet)
