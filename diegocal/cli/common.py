"""What every command shares: one-line errors, default output paths, the robot lookup, summaries."""

from __future__ import annotations

import contextlib
import functools
import logging
import os
import shlex
import sys
import threading
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console
from rich.markup import escape
from rich.table import Table

from diegocal.cli.choices import LOG_SUFFIXES
from diegocal.errors import DiegocalError, InputFileError, OptionError

console = Console(stderr=False)
errors = Console(stderr=True)


def warn(message: str) -> None:
    """One warning line on stderr (the CLI's; the library logs instead)."""
    errors.print(f"[yellow]warning:[/] {escape(str(message))}", highlight=False, soft_wrap=True)


def refuse_unconverged(whys, allow: bool, hint: str) -> None:
    """A warning line per fit that stopped at a cap (``whys``, in words; its output is written
    with converged: false), then exit 1 unless ``allow`` (``--allow-unconverged``), whose ``hint``
    each line then ends with."""
    whys = list(whys)
    for why in whys:
        warn(why if allow else f"{why}; {hint}")
    if whys and not allow:
        raise typer.Exit(1)


#: Where this thread's library warnings go while :func:`collected_warnings` is active.
_sink = threading.local()


class _WarningLines(logging.Handler):
    """The library's log warnings (``logging.getLogger("diegocal...")``) as ``warning:`` lines, or
    into the list of :func:`collected_warnings`; each once per command or batch job (a diagnosis
    binds its log to the robot more than once). What this thread has said is ``_sink.said``, set
    by :func:`cli_errors` and :func:`collected_warnings`; a thread without one says everything."""

    def emit(self, record: logging.LogRecord) -> None:
        text, said = record.getMessage(), getattr(_sink, "said", None)
        if said is not None:
            if text in said:
                return
            said.add(text)
        lines = getattr(_sink, "lines", None)
        if lines is not None:
            lines.append(text)
        else:
            warn(text)


@contextlib.contextmanager
def collected_warnings():
    """Within the block, the library's warnings in this thread are appended to the list it yields
    instead of printed (a batch job's warnings go with its outcome), each once."""
    _sink.lines, saved, _sink.said = (lines := []), getattr(_sink, "said", None), set()
    try:
        yield lines
    finally:
        del _sink.lines
        _sink.said = saved


def _install_warning_handler() -> None:
    root = logging.getLogger("diegocal")
    if not any(isinstance(h, _WarningLines) for h in root.handlers):
        handler = _WarningLines(logging.WARNING)
        root.addHandler(handler)


_install_warning_handler()


#: The `--robot` option of a command that reads a log: its default is the robot the log names.
RobotOfLog = Annotated[
    str | None,
    typer.Option("--robot", help="Robot directory or bundled robot name; by default the robot the log names."),
]


def command_line(default: str) -> str:
    """The command as typed (for the bundle header), or ``default`` when run without argv."""
    args = sys.argv[1:]
    return "diegocal " + " ".join(shlex.quote(a) for a in args) if args else default


def fail(message: str) -> typer.Exit:
    """Print one clear line on stderr and return the exit to raise."""
    errors.print(f"[bold red]error:[/] {escape(str(message))}", highlight=False, soft_wrap=True)
    return typer.Exit(1)


def usage_error(command: str, message: str) -> typer.Exit:
    """A bad option value found after parsing (it needs the data): one line, exit 2, like the
    parser's own usage errors."""
    errors.print(escape(f"error: diegocal {command}: {message} (see --help)"), highlight=False, soft_wrap=True)
    return typer.Exit(2)


def output_path(value):
    """Callback of every option naming an output (a file, or a directory a command creates): it
    needs a name (``-o ""`` is a usage error, exit 2) and its folder must exist (a command never
    creates folders: a mistyped path would scatter results); InputFileError otherwise (one line,
    exit 1), before any work. Takes one path or a tuple of them."""
    for path in value if isinstance(value, (tuple, list)) else (value,):
        if path is not None and not Path(path).name:
            raise typer.BadParameter("an output needs a file name (empty, or a folder such as '.')")
    return output_folder(value)


def output_folder(value):
    """Callback of an option naming a folder for outputs (``batch -o``): its parent must exist;
    the current folder (``.``) is one."""
    for path in value if isinstance(value, (tuple, list)) else (value,):
        if path is None:
            continue
        folder = Path(path).parent
        if not folder.is_dir():
            what = "is not a folder" if folder.exists() else "does not exist"
            raise InputFileError(f"{path}: the folder {folder} {what}; create it first")
    return value


def distinct_output(outputs, inputs, apart: bool = False) -> None:
    """Refuse an output that names one of the command's inputs (the log, a model, a URDF given as
    --robot; OptionError: one line, exit 2), before any work: writing it would replace the file it
    is made from. ``apart``: the outputs must name different files too."""
    outputs = [Path(o) for o in outputs if o is not None]
    for k, out in enumerate(outputs):
        for given in inputs:
            if given is not None and str(given).strip() and _same_file(out, Path(given)):
                raise OptionError(f"the output {out} is {given}, an input of the command: name another file")
        if apart and any(_same_file(out, other) for other in outputs[k + 1 :]):
            raise OptionError(f"two outputs are one file, {out}: name them apart")


def _same_file(a: Path, b: Path) -> bool:
    if a.exists() and b.exists():
        return os.path.samefile(a, b)
    return a.resolve() == b.resolve()


def log_output(value):
    """Callback of options naming a log to write: a .h5, .hdf5 or .csv file (else a usage error,
    exit 2) in an existing folder (:func:`output_path`)."""
    for path in value if isinstance(value, (tuple, list)) else (value,):
        if path is not None and Path(path).suffix.lower() not in LOG_SUFFIXES:
            raise typer.BadParameter(f"{path}: a log is written as .h5, .hdf5 or .csv")
    return output_path(value)


def comma_list(allowed: tuple[str, ...], none_word: str | None = None):
    """A callback checking a comma-separated option at parse time (a bad word is a usage error,
    exit 2); ``none_word`` alone stands for the empty list."""

    def check(text: str | None) -> str | None:
        if text is None:
            return None
        words = [w.strip() for w in text.split(",") if w.strip()]
        if none_word is not None and words == [none_word]:
            return text
        bad = [w for w in words if w not in allowed]
        if bad or not words:
            also = f" or {none_word}" if none_word else ""
            raise typer.BadParameter(f"{text!r}: expected a comma-separated list of {', '.join(allowed)}{also}")
        return text

    return check


def positive(value: float | None) -> float | None:
    """Callback of options that must be more than 0 (a duration, a rate): else exit 2."""
    if value is not None and not value > 0:
        raise typer.BadParameter(f"{value:g} is not more than 0")
    return value


def split_words(text: str | None) -> tuple[str, ...]:
    """``"a, b"`` -> ``("a", "b")``."""
    return tuple(w.strip() for w in (text or "").split(",") if w.strip())


def error_message(exc: BaseException) -> str:
    """The one line that says what went wrong: a library error's own message, a file system
    error's file and reason, anything else as an internal error with its type."""
    if isinstance(exc, DiegocalError):
        return str(exc)
    if isinstance(exc, OSError):
        return f"{exc.filename or ''}: {exc.strerror or exc}".lstrip(": ")
    if isinstance(exc, MemoryError):
        return "out of memory"
    return f"internal error: {type(exc).__name__}: {exc}"


def cli_errors(fn):
    """Turn library errors into one line and exit 1 (STYLE.md: the CLI alone does this); a bad
    option value the library finds (:class:`~diegocal.errors.OptionError`) exits 2.

    Unexpected exceptions also become one line, with a pointer to DIEGOCAL_DEBUG=1 for the traceback.
    """

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        _sink.said = set()  # this command's warnings, each said once
        try:
            return fn(*args, **kwargs)
        except (typer.Exit, typer.Abort, typer.TyperException):  # exits, and usage errors (exit 2)
            raise
        except OptionError as exc:  # a bad option value the parser could not see: a usage error
            raise typer.BadParameter(str(exc)) from None
        except KeyboardInterrupt:
            raise fail("interrupted; no output was written") from None
        except (DiegocalError, OSError, MemoryError) as exc:
            raise fail(error_message(exc)) from None
        except Exception as exc:  # noqa: BLE001 - the user must never see a traceback
            if os.environ.get("DIEGOCAL_DEBUG"):
                raise
            raise fail(f"{error_message(exc)} (set DIEGOCAL_DEBUG=1 for a traceback)") from None
        finally:
            _sink.said = None  # the library, called after the command, says every warning

    return wrapper


def default_output(log_path: Path, suffix: str) -> Path:
    """DESIGN.md: ``-o`` defaults to a file beside the log named after the command (logs.calib.yaml)."""
    log_path = Path(log_path)
    return log_path.with_name(log_path.name.rsplit(".", 1)[0] + suffix)


def summary(title: str, rows, columns=("quantity", "value"), quiet: bool = False) -> None:
    """Every command ends with a short summary table (DESIGN.md conventions)."""
    if quiet:
        return
    table = Table(title=escape(title), title_justify="left")
    for c in columns:
        table.add_column(str(c))
    for row in rows:
        table.add_row(*[_fmt(v) for v in row])
    console.print(table)


def _fmt(v) -> str:
    """A summary cell as written (a file or column name's brackets are text, not rich markup)."""
    if isinstance(v, float):
        return f"{v:.4g}"
    return escape(str(v))


def progress_enabled(quiet: bool) -> bool:
    return not quiet and sys.stderr.isatty()


def eta_lines(what: str, total: int, quiet: bool):
    """A callable to call as each of ``total`` items of a long loop finishes (any arguments): every
    few seconds it prints on stderr how far ``what`` is, with the time left
    (:class:`diegocal.progress.Eta`); None with --quiet."""
    if quiet:
        return None
    from diegocal.progress import Eta  # lazy: the help reads this module

    eta, done = Eta(total), [0]

    def step(*_) -> None:
        done[0] += 1
        if eta.due(done[0]):
            errors.print(f"[dim]{what}:[/] {eta.text(done[0])}", highlight=False)

    return step
