"""`diegocal report RESULT... -o report.pdf`: the document, and its summary in plain words on the terminal."""

import shlex
import sys
from pathlib import Path
from typing import Annotated

import typer

from diegocal.cli.app import app
from diegocal.cli.common import cli_errors, default_output, distinct_output, output_path, summary


@app.command("report")
@cli_errors
def report(
    results: Annotated[
        list[Path],
        typer.Argument(
            help="Logs and fitted results (calib.yaml, pneumatic.yaml, sgp/, diagnosis.yaml, batch tables)."
        ),
    ],
    output: Annotated[
        Path | None,
        typer.Option(
            "-o",
            "--output",
            callback=output_path,
            help="PDF document to write; by default RESULT.report.pdf beside the first result.",
        ),
    ] = None,
    robot: Annotated[
        Path | None,
        typer.Option(
            "--robot",
            help="Robot directory, for sections that draw the robot; by default the robot each result records.",
        ),
    ] = None,
    heldout: Annotated[
        list[Path] | None,
        typer.Option(
            "--heldout",
            help="Held-out log (repeatable): each fitted model of the same robot is scored on it.",
        ),
    ] = None,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No summary on the terminal.")] = False,
) -> None:
    """Write one PDF document: contents and summary, then one section per result; print the summary."""
    # Imported here, not at the top: the report loads matplotlib and every model family, which the
    # CLI's start-up (`diegocal --help`) must not wait for.
    from diegocal.errors import InputFileError
    from diegocal.report import ReportContext, write_report
    from diegocal.report.pdf import headlines, plan_report

    out = output or default_output(results[0], ".report.pdf")
    distinct_output((out,), (*results, *(heldout or ())))
    for h in heldout or ():
        if not h.is_file():
            raise InputFileError(f"{h}: no such held-out log")
    command = "diegocal " + " ".join(shlex.quote(a) for a in sys.argv[1:]) if sys.argv[1:] else "diegocal report"
    context = ReportContext(robot=robot, heldout=tuple(heldout or ()))
    write_report(results, out, context, command=command)
    if quiet:
        return
    rows = [(title, line) for title, line in headlines(plan_report(results), context)]  # cached: not recomputed
    summary(f"report → {out}: what was calibrated and what was found wrong", rows, ("result", "summary"))
