"""`diegocal report RESULT... -o report.pdf`."""

import shlex
import sys
from pathlib import Path
from typing import Annotated

import typer

from diegocal.cli.app import app
from diegocal.cli.common import cli_errors, default_output, summary
from diegocal.report import ReportContext, write_report


@app.command("report")
@cli_errors
def report(
    results: Annotated[list[Path], typer.Argument(help="Logs and fitted results (calib.yaml, pneumatic.yaml, sgp/).")],
    output: Annotated[
        Path | None, typer.Option("-o", "--output", help="PDF to write [default: beside the first result].")
    ] = None,
    robot: Annotated[
        Path | None, typer.Option("--robot", help="Robot directory, for sections that draw the robot.")
    ] = None,
    quiet: Annotated[bool, typer.Option("--quiet", "-q")] = False,
) -> None:
    """Write one multi-page PDF: a title page, then one section per result."""
    out = output or default_output(results[0], ".report.pdf")
    command = "diegocal " + " ".join(shlex.quote(a) for a in sys.argv[1:]) if sys.argv[1:] else "diegocal report"
    sections = write_report(results, out, ReportContext(robot=robot), command=command)
    summary(
        f"report → {out}", [(str(r), s) for r, s in zip(results, sections, strict=True)], ("result", "section"), quiet
    )
