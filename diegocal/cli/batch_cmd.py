"""`diegocal batch COMMAND FOLDER|GLOB`: one command over every log, then a merged table.

parse → :func:`diegocal.batch.plan_batch` → :func:`diegocal.batch.run_batch` (each job's arguments
parsed by its command's parser, its job function run in a worker process here or on a Dask cluster)
→ merged table (CSV) and its report page (PDF) → summary; exit 1 if any log failed.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.markup import escape

from diegocal.cli.app import app
from diegocal.cli.choices import BATCH_COMMANDS
from diegocal.cli.common import cli_errors, console, errors, output_folder, output_path, summary

COMMAND_NAMES = BATCH_COMMANDS


def _command(value: str) -> str:
    if value not in COMMAND_NAMES:
        raise typer.BadParameter(f"{value!r} is not one of {', '.join(COMMAND_NAMES)}")
    return value


@app.command(
    "batch",
    context_settings={"allow_extra_args": True},
    epilog="Arguments after -- go to every run of COMMAND, e.g. diegocal batch stac logs/ -- --loss huber.",
)
@cli_errors
def batch(
    ctx: typer.Context,
    command: Annotated[
        str,
        typer.Argument(
            callback=_command, metavar="COMMAND", help="The command to run: " + ", ".join(COMMAND_NAMES) + "."
        ),
    ],
    source: Annotated[
        str,
        typer.Argument(metavar="FOLDER|GLOB", help="A folder of logs, a quoted glob such as 'logs/*.h5', or one log."),
    ],
    output_dir: Annotated[
        Path | None,
        typer.Option(
            "-o",
            "--output-dir",
            callback=output_folder,
            help="Folder for the outputs (created if its parent exists); by default each output goes beside its log.",
        ),
    ] = None,
    jobs: Annotated[int, typer.Option("--jobs", "-j", min=1, help="Logs processed at once on this machine.")] = 1,
    scheduler: Annotated[
        str | None,
        typer.Option("--scheduler", help="Address of a Dask scheduler (tcp://host:8786) to run the logs on instead."),
    ] = None,
    model: Annotated[
        Path | None, typer.Option("--model", help="For predict: the fitted model to predict every log with.")
    ] = None,
    force: Annotated[
        bool, typer.Option("--force", help="Run every log, even those whose outputs are up to date.")
    ] = False,
    table: Annotated[
        Path | None,
        typer.Option(
            "--table",
            callback=output_path,
            help="Merged table to write (CSV); by default COMMAND.batch.csv in the output folder.",
        ),
    ] = None,
    list_only: Annotated[
        bool, typer.Option("--list", help="Only print the logs the command applies to, one per line (for make).")
    ] = False,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No progress lines and no summary table.")] = False,
) -> None:
    """Run a command over every log of a folder: one output per log, skipping logs whose outputs are
    newer (as make does), and a merged table of the results (CSV and a report page)."""
    # the library is imported when the command runs, so that `--help` answers at once
    from diegocal.batch import BatchOptions, plan_batch, run_batch, save_table

    if scheduler and jobs > 1:  # a usage error: one line, exit 2, as the parser's own
        errors.print("error: diegocal batch: give --jobs or --scheduler, not both (see --help)", highlight=False)
        raise typer.Exit(2)
    options = BatchOptions(output_dir=output_dir, extra=tuple(ctx.args), model=model, force=force)
    plan = plan_batch(command, source, options)
    if list_only:
        for log in dict.fromkeys(j.log for j in plan.jobs):
            console.print(str(log), highlight=False, soft_wrap=True)
        return
    if output_dir is not None:
        output_dir.mkdir(exist_ok=True)  # its parent exists (output_path)

    def progress(outcome, done: int, total: int) -> None:
        if quiet:
            return
        tail = f"{outcome.seconds:.1f} s" if not outcome.failed else outcome.message
        label, tail = escape(outcome.job.label), escape(tail)
        errors.print(f"[dim]batch \\[{done}/{total}][/] {outcome.status:<6} {label}  {tail}", highlight=False)
        for line in outcome.warnings:
            errors.print(f"  [yellow]warning:[/] {escape(line)}", highlight=False, soft_wrap=True)

    outcomes = run_batch(plan.jobs, jobs, scheduler, progress)
    csv_path = table or (output_dir or _table_dir(plan)) / f"{command}.batch.csv"
    save_table(plan, outcomes, csv_path)
    pdf_path = csv_path.with_suffix(".pdf")
    _report(csv_path, pdf_path)
    failed = [o for o in outcomes if o.failed]
    counts = {s: sum(o.status == s for o in outcomes) for s in ("done", "up to date", "failed")}
    rows = [(status, n) for status, n in counts.items()]
    rows += [("not applicable", len(plan.not_applicable)), ("table", str(csv_path)), ("report page", str(pdf_path))]
    summary(f"batch {command} {source}", rows, quiet=quiet)
    if not quiet:
        for path, reason in plan.not_applicable.items():
            errors.print(escape(f"skipped {path}: {reason}"), highlight=False, soft_wrap=True)
    for o in failed:  # one line each, even with --quiet
        errors.print(
            f"[bold red]failed:[/] {escape(o.job.label)}: {escape(o.message)}", highlight=False, soft_wrap=True
        )
    if failed:
        raise typer.Exit(1)


def _table_dir(plan) -> Path:
    source = Path(plan.source)
    return source if source.is_dir() else plan.jobs[0].log.parent


def _report(csv_path: Path, pdf_path: Path) -> None:
    from diegocal.report import write_report

    write_report([csv_path], pdf_path, command=f"diegocal report {csv_path}")
