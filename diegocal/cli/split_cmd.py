"""`diegocal split LOG --at FRACTION|SECONDS -o TRAIN HELDOUT`: a held-out part of the same session.

The log is cut once, in time: TRAIN is every sample before the cut, HELDOUT every sample from it on
(contiguous blocks; samples 10 ms apart are not independent, so no shuffling). Both keep the log's
robot, rate and, for a simulated log, the truth of their samples. Both files are written together,
atomically (neither is left behind when one fails).
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from diegocal.cli.app import app
from diegocal.cli.common import cli_errors, log_output, summary, usage_error


def parse_at(text: str) -> tuple[float, str]:
    """``0.8`` or ``80%`` -> (0.8, 'fraction'); ``120`` or ``120s`` -> (120.0, 'seconds')."""
    raw = text.strip().lower()
    unit = "fraction" if raw.endswith("%") else "seconds" if raw.endswith("s") else None
    number = raw.rstrip("%s").strip()
    try:
        value = float(number)
    except ValueError:
        raise ValueError(f"--at {text!r}: expected a fraction (0.8, 80%) or seconds (120, 120s)") from None
    if unit == "fraction":
        return value / 100.0, unit
    if unit is None:
        unit = "fraction" if 0.0 < value < 1.0 else "seconds"
    return value, unit


@app.command("split")
@cli_errors
def split(
    log: Annotated[Path, typer.Argument(help="The log to cut (.h5 or .csv).")],
    at: Annotated[
        str,
        typer.Option(
            "--at",
            help="Where to cut: a fraction of the samples (0.8 or 80%) or seconds from the start (120 or 120s; "
            "a number of 1 or more is seconds).",
        ),
    ],
    output: Annotated[
        tuple[Path, Path] | None,
        typer.Option(
            "-o",
            "--output",
            callback=log_output,
            help="The two logs to write, TRAIN then HELDOUT (.h5 or .csv); by default LOG.train.h5 and "
            "LOG.heldout.h5 beside the log.",
        ),
    ] = None,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No summary table.")] = False,
) -> None:
    """Cut a log in two contiguous parts in time: TRAIN to fit on, HELDOUT to predict."""
    # the library is imported when the command runs, so that `--help` answers at once
    from diegocal.io import load_log, save_logs, split_log

    try:
        value, unit = parse_at(at)
    except ValueError as exc:
        raise usage_error("split", str(exc)) from None
    if output is None:
        stem = log.name.rsplit(".", 1)[0]
        suffix = log.suffix if log.suffix.lower() in (".h5", ".hdf5", ".csv") else ".h5"
        output = (log.with_name(f"{stem}.train{suffix}"), log.with_name(f"{stem}.heldout{suffix}"))
    train_path, held_path = output
    if Path(train_path).resolve() == Path(held_path).resolve() or Path(log).resolve() in (
        Path(train_path).resolve(),
        Path(held_path).resolve(),
    ):
        raise usage_error("split", "-o needs two new files, distinct from each other and from LOG")
    data = load_log(log)
    try:
        train, held = split_log(data, value, unit)
    except ValueError as exc:
        raise usage_error("split", f"--at {at}: {exc}") from None
    save_logs([(train, train_path), (held, held_path)])
    rows = [
        ("cut at", f"{held.time[0] - data.time[0]:.6g} s (sample {train.n_samples} of {data.n_samples})"),
        ("train", f"{train_path}  ({train.n_samples} samples, {train.duration:.4g} s)"),
        ("held out", f"{held_path}  ({held.n_samples} samples, {held.duration:.4g} s)"),
    ]
    summary(f"split {log.name}", rows, quiet=quiet)
