"""What every command shares: one-line errors, default output paths, the robot lookup, summaries."""

from __future__ import annotations

import functools
import os
import sys
from pathlib import Path

import typer
from rich.console import Console
from rich.table import Table

from diegocal.errors import DiegocalError

console = Console(stderr=False)
errors = Console(stderr=True)


def fail(message: str) -> typer.Exit:
    """Print one clear line on stderr and return the exit to raise."""
    errors.print(f"[bold red]error:[/] {message}", highlight=False, soft_wrap=True)
    return typer.Exit(1)


def cli_errors(fn):
    """Turn library errors into one line and exit 1 (STYLE.md: the CLI alone does this).

    Unexpected exceptions also become one line, with a pointer to DIEGOCAL_DEBUG=1 for the traceback.
    """

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        try:
            return fn(*args, **kwargs)
        except (typer.Exit, typer.Abort):
            raise
        except DiegocalError as exc:
            raise fail(str(exc)) from None
        except OSError as exc:
            raise fail(f"{exc.filename or ''}: {exc.strerror or exc}".lstrip(": ")) from None
        except KeyboardInterrupt:
            raise fail("interrupted; no output was written") from None
        except Exception as exc:  # noqa: BLE001 - the user must never see a traceback
            if os.environ.get("DIEGOCAL_DEBUG"):
                raise
            raise fail(f"internal error: {type(exc).__name__}: {exc} (set DIEGOCAL_DEBUG=1 for a traceback)") from None

    return wrapper


def default_output(log_path: Path, suffix: str) -> Path:
    """DESIGN.md: ``-o`` defaults to a file beside the log named after the command (logs.calib.yaml)."""
    log_path = Path(log_path)
    return log_path.with_name(log_path.name.rsplit(".", 1)[0] + suffix)


def summary(title: str, rows, columns=("quantity", "value"), quiet: bool = False) -> None:
    """Every command ends with a short summary table (DESIGN.md conventions)."""
    if quiet:
        return
    table = Table(title=title, title_justify="left")
    for c in columns:
        table.add_column(str(c))
    for row in rows:
        table.add_row(*[_fmt(v) for v in row])
    console.print(table)


def _fmt(v) -> str:
    if isinstance(v, float):
        return f"{v:.4g}"
    return str(v)


def progress_enabled(quiet: bool) -> bool:
    return not quiet and sys.stderr.isatty()
