"""Run one command over every log of a folder (or glob): locally in processes, or on a Dask cluster.

``diegocal batch stac logs/`` plans one job per log (per log and domain for ``diagnose``), skips the
jobs whose outputs are newer than their inputs (as make does), runs the rest, each as its own
``diegocal`` process, and writes a merged table of the results::

    plan = plan_batch("stac", "logs/", BatchOptions(output_dir=Path("out")))
    outcomes = run_batch(plan.jobs, jobs=2)                       # or scheduler="tcp://host:8786"
    save_table(plan, outcomes, Path("out/stac.batch.csv"))

A job runs the ordinary command line (``python -m diegocal stac LOG -o OUT --quiet``), so a job on a
cluster needs diegocal installed on the workers and the logs on a file system they share. One
failed log never stops the others: its outcome carries the one-line error the command printed.

Which files are logs. A folder contributes its ``*.h5``, ``*.hdf5`` and ``*.csv`` files that are
diegocal logs (HDF5 ``format`` attribute ``diegocal-log``; CSV with the ``# diegocal-log`` header or a
``time`` column) and are not outputs of diegocal itself (``*.prediction.h5``, a batch table,
joint-angle files ``*.q.h5`` of older versions); logs without the streams the command needs are
listed as not applicable, not failed. Outputs never match these rules, so running a batch twice,
even with its outputs beside the logs, finds the same logs.
"""

from __future__ import annotations

import glob
import os
import shlex
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from diegocal.domains import DOMAINS
from diegocal.domains import domain as domain_record
from diegocal.errors import DiegocalError, InputFileError

#: File name endings of logs; anything else in a folder is not looked at.
LOG_SUFFIXES = (".h5", ".hdf5", ".csv")
#: Logs diegocal itself writes (predictions, joint angles of older stac versions) and batch tables.
DERIVED_SUFFIXES = (".prediction.h5", ".prediction.csv", ".q.h5", ".batch.csv")
#: The header line of a merged batch table (so that the report recognises it and no batch takes it for a log).
TABLE_HEADER = "# diegocal-batch"
#: Threads per process when several jobs share the machine (BLAS would otherwise oversubscribe it).
THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


@dataclass(frozen=True)
class CommandSpec:
    """How batch runs one diegocal command: its output's suffix and the streams a log needs."""

    name: str
    suffix: str  # output name = log stem + suffix; "{domain}" is filled in for diagnose
    needs: tuple[str, ...] = ()
    directory: bool = False  # the output is a directory (the sgp bundle); its summary file dates it


COMMANDS = {
    **{
        d.fit_command: CommandSpec(d.fit_command, d.model_suffix, d.fit_needs, directory=d.model_is_directory)
        for d in DOMAINS.values()
    },
    "diagnose": CommandSpec("diagnose", ".{domain}.diagnosis.yaml"),
    "predict": CommandSpec("predict", ".prediction.h5"),
}


@dataclass(frozen=True)
class BatchOptions:
    """Options of a batch, parsed once.

    output_dir : folder for every output (None: beside each log, as each command's default)
    extra : arguments passed on to every run of the command (e.g. ``("--loss", "huber")``)
    model : the fitted model `predict` uses (required for predict only)
    force : run every job, even those whose outputs are up to date
    """

    output_dir: Path | None = None
    extra: tuple[str, ...] = ()
    model: Path | None = None
    force: bool = False


@dataclass(frozen=True)
class Job:
    """One run of a command on one log (and one domain, for diagnose)."""

    command: str
    log: Path
    output: Path
    argv: tuple[str, ...]  # the command line after ``diegocal``
    inputs: tuple[Path, ...]  # the files the output depends on (the log, the model)
    domain: str | None = None
    up_to_date: bool = False

    @property
    def label(self) -> str:
        return self.log.name + (f" [{self.domain}]" if self.domain else "")


@dataclass(frozen=True)
class Plan:
    """What a batch will do: the jobs, in order, and the files it did not take, with the reason."""

    command: str
    source: str
    jobs: tuple[Job, ...]
    not_applicable: dict = field(default_factory=dict)  # path -> reason


@dataclass(frozen=True)
class Outcome:
    """How one job ended: status "done", "up to date" or "failed"; ``message`` is the failure's one line."""

    job: Job
    status: str
    seconds: float = 0.0
    message: str = ""

    @property
    def failed(self) -> bool:
        return self.status == "failed"


# ----------------------------------------------------------------------------- discovery
def find_logs(source) -> list[Path]:
    """The candidate log files of a folder (not recursive) or a glob pattern, sorted; derived files
    (:data:`DERIVED_SUFFIXES`) are left out. Raises InputFileError when nothing matches."""
    text = str(source)
    path = Path(text)
    if path.is_dir():
        files = [p for p in path.iterdir() if p.is_file() and p.suffix.lower() in LOG_SUFFIXES]
    elif path.is_file():
        files = [path]
    elif glob.has_magic(text):
        files = [Path(p) for p in glob.glob(text) if Path(p).is_file()]
    else:
        raise InputFileError(f"{text}: no such folder or file (give a folder of logs or a quoted glob)")
    files = sorted(p for p in files if not p.name.lower().endswith(DERIVED_SUFFIXES))
    if not files:
        raise InputFileError(f"{text}: no log files (*.h5, *.hdf5, *.csv) there")
    return files


def _streams(path: Path) -> tuple[str, ...] | str:
    """The log's stream names, or the reason it is not a log."""
    from diegocal.io.files import log_streams

    try:
        return log_streams(path)
    except DiegocalError as exc:
        return str(exc).removeprefix(f"{path}: ")


# ----------------------------------------------------------------------------- planning
def plan_batch(command: str, source, options: BatchOptions = BatchOptions()) -> Plan:
    """The jobs of ``command`` over the logs of ``source`` (a folder, a glob or one file).

    Raises DiegocalError for an unknown command, a missing model (predict) or when no log applies.
    """
    if command not in COMMANDS:
        raise DiegocalError(f"batch cannot run {command!r}; it runs {', '.join(COMMANDS)}")
    spec = COMMANDS[command]
    needs = _needs(command, options)
    jobs, skipped = [], {}
    for log in find_logs(source):
        streams = _streams(log)
        if isinstance(streams, str):
            skipped[log] = f"not a diegocal log ({streams})"
            continue
        units = _units(command, streams, needs, options)
        if isinstance(units, str):
            skipped[log] = units
            continue
        for domain in units:
            jobs.append(_job(spec, log, domain, options))
    if not jobs:
        reasons = "; ".join(f"{p.name}: {r}" for p, r in list(skipped.items())[:3])
        raise InputFileError(f"{source}: no log that {command} can use ({reasons})")
    return Plan(command, str(source), tuple(jobs), skipped)


def _needs(command: str, options: BatchOptions) -> tuple[str, ...]:
    if command != "predict":
        return COMMANDS[command].needs
    if options.model is None:
        raise InputFileError("batch predict needs the fitted model: --model calib.yaml | pneumatic.yaml | DIR.sgp")
    from diegocal.io.bundle import load_bundle

    bundle = load_bundle(options.model)
    if bundle.kind == "diagnosis":
        return domain_record(bundle.data.get("domain")).predict_needs if bundle.data.get("domain") else ()
    return domain_record(bundle.kind).predict_needs


def _units(command: str, streams, needs, options: BatchOptions):
    """The domains to run for one log ([None] for commands without domains), or why none applies."""
    if command == "diagnose":
        wanted = _option_values(options.extra, "--domain") or list(DOMAINS)
        domains = [d for d in wanted if d in DOMAINS and all(s in streams for s in DOMAINS[d].streams)]
        if not domains:
            return f"no domain to diagnose (streams: {', '.join(streams) or 'none'})"
        return domains
    missing = [s for s in needs if s not in streams]
    if missing:
        return f"no {', '.join(missing)} stream{'s' if len(missing) > 1 else ''} (needed by {command})"
    return [None]


def _option_values(extra: Sequence[str], name: str) -> list[str]:
    out = []
    for i, a in enumerate(extra):
        if a == name and i + 1 < len(extra):
            out.append(extra[i + 1])
        elif a.startswith(name + "="):
            out.append(a.split("=", 1)[1])
    return out


def _without_option(extra: Sequence[str], name: str) -> tuple[str, ...]:
    out, skip = [], False
    for a in extra:
        if skip:
            skip = False
        elif a == name:
            skip = True
        elif not a.startswith(name + "="):
            out.append(a)
    return tuple(out)


def output_path(command: str, log: Path, output_dir: Path | None = None, domain: str | None = None) -> Path:
    """Where batch puts ``command``'s output for ``log``: ``<dir>/<log stem><suffix>``."""
    suffix = COMMANDS[command].suffix.replace("{domain}", domain or "")
    return (output_dir or log.parent) / (log.name.rsplit(".", 1)[0] + suffix)


def _job(spec: CommandSpec, log: Path, domain: str | None, options: BatchOptions) -> Job:
    out = output_path(spec.name, log, options.output_dir, domain)
    extra = options.extra
    if spec.name == "predict":
        argv = ("predict", str(options.model), str(log), "-o", str(out))
        inputs = (log, options.model)
    else:
        argv = (spec.name, str(log), "-o", str(out))
        inputs = (log,)
    if spec.name == "diagnose":
        extra = _without_option(extra, "--domain")
        argv += ("--domain", str(domain))
    if spec.name == "pneumatic-fit" and not _option_values(extra, "--chamber") and "--all" not in extra:
        argv += ("--all",)
    argv += (*extra, "--quiet")
    stamp = out / "sgp.yaml" if spec.directory else out
    fresh = not options.force and _newer(stamp, inputs)
    return Job(spec.name, log, out, argv, inputs, domain, fresh)


def _newer(output: Path, inputs) -> bool:
    """Whether ``output`` exists and is at least as new as every input (make's rule)."""
    try:
        t = output.stat().st_mtime
        return all(t >= Path(i).stat().st_mtime for i in inputs)
    except OSError:
        return False


# ----------------------------------------------------------------------------- running
def run_job(job: Job) -> Outcome:
    """Run one job as its own ``diegocal`` process; never raises (a failure is an Outcome).

    The process is the ordinary command line, so a job behaves exactly as the command typed by
    hand; its last "error:" line (or its last line) is the failure's reason.
    """
    if job.up_to_date:
        return Outcome(job, "up to date")
    start = time.perf_counter()
    try:
        proc = subprocess.run(
            [sys.executable, "-m", "diegocal", *job.argv], capture_output=True, text=True, check=False, env=_env()
        )
    except OSError as exc:
        return Outcome(job, "failed", time.perf_counter() - start, f"cannot start diegocal: {exc}")
    seconds = time.perf_counter() - start
    if proc.returncode == 0:
        return Outcome(job, "done", seconds)
    return Outcome(job, "failed", seconds, _reason(proc))


def _env() -> dict:
    """This process's environment, with the diegocal it runs first on the path (so that a job runs
    the same code as the batch, installed or not)."""
    import diegocal

    root = str(Path(diegocal.__file__).resolve().parent.parent)
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([root] + [p for p in env.get("PYTHONPATH", "").split(os.pathsep) if p])
    return env


def _reason(proc: subprocess.CompletedProcess) -> str:
    lines = [ln.strip() for ln in (proc.stderr or "").splitlines() + (proc.stdout or "").splitlines() if ln.strip()]
    errors = [ln for ln in lines if ln.startswith("error:")]
    if errors:
        return errors[-1].removeprefix("error:").strip()
    if proc.returncode < 0:
        return f"killed by signal {-proc.returncode}" + (" (out of memory?)" if proc.returncode == -9 else "")
    return lines[-1] if lines else f"exit status {proc.returncode}"


def run_batch(
    jobs: Sequence[Job],
    jobs_n: int = 1,
    scheduler: str | None = None,
    progress: Callable[[Outcome, int, int], None] | None = None,
) -> list[Outcome]:
    """Run the jobs: ``jobs_n`` at a time on this machine, or on the Dask cluster at ``scheduler``.

    Returns one Outcome per job, in the jobs' order; ``progress(outcome, done, total)`` is called
    as each finishes. Raises DiegocalError when the scheduler cannot be reached.
    """
    outcomes: dict[int, Outcome] = {}
    todo = [(i, j) for i, j in enumerate(jobs) if not j.up_to_date]
    for i, j in enumerate(jobs):
        if j.up_to_date:
            outcomes[i] = Outcome(j, "up to date")
    total = len(todo)

    def record(i: int, outcome: Outcome) -> None:
        outcomes[i] = outcome
        if progress is not None:
            progress(outcome, len(outcomes) - (len(jobs) - total), total)

    if todo and scheduler:
        _run_dask(todo, scheduler, record)
    elif todo:
        _run_local(todo, jobs_n, record)
    return [outcomes[i] for i in range(len(jobs))]


def _run_local(todo, jobs_n: int, record) -> None:
    from concurrent.futures import ThreadPoolExecutor, as_completed

    if jobs_n > 1:  # one BLAS thread per process, unless the user chose otherwise
        for var in THREAD_VARS:
            os.environ.setdefault(var, "1")
    with ThreadPoolExecutor(max_workers=max(1, jobs_n)) as pool:  # each thread waits on its own process
        futures = {pool.submit(run_job, job): i for i, job in todo}
        for fut in as_completed(futures):
            record(futures[fut], fut.result())


def _run_dask(todo, address: str, record) -> None:
    try:
        from distributed import Client, as_completed
    except ImportError:
        raise DiegocalError("--scheduler needs dask.distributed: pip install 'dask[distributed]'") from None
    try:
        client = Client(address, timeout="10s")
    except (OSError, TimeoutError, ValueError) as exc:
        raise DiegocalError(f"cannot reach the Dask scheduler at {address}: {exc}") from None
    with client:
        futures = client.map(run_job, [job for _, job in todo], pure=False)
        index = {f.key: i for f, (i, _) in zip(futures, todo, strict=True)}
        jobs = dict(todo)
        for fut in as_completed(futures):
            i = index[fut.key]
            try:
                outcome = fut.result()
            except Exception as exc:  # noqa: BLE001 - a lost worker fails its job, not the batch
                outcome = Outcome(jobs[i], "failed", 0.0, f"Dask task failed: {type(exc).__name__}: {exc}")
            record(i, outcome)


def command_line(job: Job) -> str:
    """The job as the user would type it."""
    return "diegocal " + " ".join(shlex.quote(a) for a in job.argv)
