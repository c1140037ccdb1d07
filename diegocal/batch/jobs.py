"""Run one command over every log of a folder (or glob): locally in a process pool, or on a Dask cluster.

``diegocal batch stac logs/`` plans one job per log (per log and domain for ``diagnose``), skips the
jobs whose outputs are newer than their inputs (as make does), runs the rest and writes a merged
table of the results::

    plan = plan_batch("stac", "logs/", BatchOptions(output_dir=Path("out")))
    outcomes = run_batch(plan.jobs, jobs_n=2)                     # or scheduler="tcp://host:8786"
    save_table(plan, outcomes, Path("out/stac.batch.csv"))

A job is the command without its shell: its arguments are parsed by the command's own parser (as
``diegocal stac LOG -o OUT --quiet ...`` typed by hand would be) into the command's options
dataclass, and its job function (load → library call → save, e.g.
:func:`diegocal.cli.stac_cmd.run_stac`) runs in a worker process, or as a plain function submitted
to a Dask cluster (which needs diegocal installed on the workers and the logs on a file system they
share). One failed log never stops the others: its outcome carries the message of the exception
that failed it. A job fails when its function raises, when its process dies, or when what it wrote
says it must not be used (a calibration that did not converge, unless the job's arguments allow it).

Which files are logs. A folder contributes its ``*.h5``, ``*.hdf5`` and ``*.csv`` files that are
not outputs of diegocal itself (``*.prediction.h5``, a batch table, joint-angle files ``*.q.h5`` of
older versions). Another program's file (an HDF5 file without the diegocal ``format`` attribute, a
CSV without the ``# diegocal-log`` header or a ``time`` column) and a log without the streams the
command needs are listed as not applicable; a file that cannot be read (a truncated HDF5 file, a
``.h5`` that is no HDF5 file) is a failed job. Outputs never match these rules, so running a batch
twice, even with its outputs beside the logs, finds the same logs.
"""

from __future__ import annotations

import functools
import glob
import importlib
import os
import shlex
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from diegocal.domains import DOMAINS
from diegocal.domains import domain as domain_record
from diegocal.errors import DamagedFileError, DiegocalError, InputFileError, LogFormatError, OptionError

#: File name endings of logs; anything else in a folder is not looked at.
LOG_SUFFIXES = (".h5", ".hdf5", ".csv")
#: Logs diegocal itself writes (predictions, joint angles of older stac versions) and batch tables.
DERIVED_SUFFIXES = (".prediction.h5", ".prediction.csv", ".q.h5", ".batch.csv")
#: The header line of a merged batch table (so that the report recognises it and no batch takes it for a log).
TABLE_HEADER = "# diegocal-batch"
#: Threads per process when several jobs share the machine (BLAS would otherwise oversubscribe it).
THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
#: The failure of a job whose process died under it.
DIED = "its process died (killed by the system: out of memory?)"


@dataclass(frozen=True)
class CommandSpec:
    """How batch runs one diegocal command: its output's suffix, the streams a log needs, and where
    its options dataclass, its job function and the check of what it wrote are (in ``module``)."""

    name: str
    suffix: str  # output name = log stem + suffix; "{domain}" is filled in for diagnose
    module: str
    args: str  # the options dataclass, built from the parsed parameters
    run: str  # run(args, command) -> result: load -> library call -> save; raises DiegocalError
    needs: tuple[str, ...] = ()
    directory: bool = False  # the output is a directory (the sgp bundle); its summary file dates it
    verdict: str | None = None  # verdict(args) -> why the output it wrote is a failure, or None


def _fit(domain: str, module: str, args: str, run: str, verdict: str | None = None) -> CommandSpec:
    """The spec of a domain's fit command (its output suffix and needed streams from the Domain record)."""
    d = DOMAINS[domain]
    return CommandSpec(d.fit_command, d.model_suffix, module, args, run, d.fit_needs, d.model_is_directory, verdict)


CLI = "diegocal.cli."
#: Command name -> how batch runs it.
COMMANDS = {
    spec.name: spec
    for spec in (
        _fit("kinematics", CLI + "stac_cmd", "StacArgs", "run_stac", "written_verdict"),
        _fit("dynamics", CLI + "sgp_cmd", "SgpArgs", "run_sgp", "written_verdict"),
        _fit("pneumatics", CLI + "pneumatic_cmd", "PneumaticArgs", "run_pneumatic", "written_verdict"),
        CommandSpec(
            "diagnose", ".{domain}.diagnosis.yaml", CLI + "diagnose_cmd", "DiagnoseArgs", "run_diagnose",
            verdict="written_verdict",
        ),
        CommandSpec("predict", ".prediction.h5", CLI + "predict_cmd", "PredictArgs", "run_predict"),
    )
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
    """One run of a command on one log (and one domain, for diagnose).

    problem : why the log cannot be read (the job fails without running), or ""."""

    command: str
    log: Path
    output: Path
    argv: tuple[str, ...]  # the command line after ``diegocal``
    inputs: tuple[Path, ...]  # the files the output depends on (the log, the model)
    domain: str | None = None
    up_to_date: bool = False
    problem: str = ""

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
    """How one job ended: status "done", "up to date" or "failed"; ``message`` is the failure's one
    line (the message of the exception that failed it); ``judged``: failed by what its output says
    (the output is the job's own, its numbers go in the table); ``warnings``: what the job warned of."""

    job: Job
    status: str
    seconds: float = 0.0
    message: str = ""
    judged: bool = False
    warnings: tuple[str, ...] = ()

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


def _streams(path: Path) -> tuple[str, tuple[str, ...] | str]:
    """("log", its stream names), ("other", why it is another program's file) or ("unreadable",
    why the log cannot be read)."""
    from diegocal.io.files import log_streams

    try:
        return "log", log_streams(path)
    except DiegocalError as exc:
        reason = str(exc).removeprefix(f"{path}: ")
        other = isinstance(exc, LogFormatError) and not isinstance(exc, DamagedFileError) and _readable(path)
        return ("other" if other else "unreadable"), reason


def _readable(path: Path) -> bool:
    """Whether a file that is no diegocal log reads as another kind of file: a CSV, or an HDF5 file
    that opens (a truncated one does not; nor does a ``.h5`` that is no HDF5 file)."""
    if path.suffix.lower() == ".csv":
        return True
    import h5py

    try:
        with h5py.File(path, "r"):
            return True
    except OSError:
        return False


# ----------------------------------------------------------------------------- planning
def plan_batch(command: str, source, options: BatchOptions = BatchOptions()) -> Plan:
    """The jobs of ``command`` over the logs of ``source`` (a folder, a glob or one file).

    Raises DiegocalError for an unknown command, a missing model (predict) or when no log applies;
    OptionError when ``options.extra`` are not arguments the command takes.
    """
    if command not in COMMANDS:
        raise DiegocalError(f"batch cannot run {command!r}; it runs {', '.join(COMMANDS)}")
    spec = COMMANDS[command]
    needs = _needs(command, options)
    extra = _extra_params(command, options.extra)
    jobs, skipped = [], {}
    for log in find_logs(source):
        kind, streams = _streams(log)
        if kind == "other":
            skipped[log] = streams
            continue
        if kind == "unreadable":  # a log that cannot be read is a failure, not "not applicable"
            jobs.append(_job(spec, log, None, options, extra, problem=streams))
            continue
        units = _units(command, streams, needs, extra)
        if isinstance(units, str):
            skipped[log] = units
            continue
        jobs.extend(_job(spec, log, domain, options, extra) for domain in units)
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


def _extra_params(command: str, extra: Sequence[str]) -> dict:
    """The command's parameters with ``extra`` (what goes to every run), parsed by its own parser
    with stand-ins for the logs: what the plan needs to know of them (diagnose's ``--domain``,
    pneumatic-fit's ``--chamber``), and a usage error before any job runs."""
    positional = ("MODEL", "LOG") if command == "predict" else ("LOG",)
    return _parse(command, (*positional, *extra))


def _units(command: str, streams, needs, extra: dict):
    """The domains to run for one log ([None] for commands without domains), or why none applies."""
    if command == "diagnose":
        wanted = [extra["domain"]] if extra.get("domain") else list(DOMAINS)
        domains = [d for d in wanted if all(s in streams for s in DOMAINS[d].streams)]
        if not domains:
            return f"no domain to diagnose (streams: {', '.join(streams) or 'none'})"
        return domains
    missing = [s for s in needs if s not in streams]
    if missing:
        return f"no {', '.join(missing)} stream{'s' if len(missing) > 1 else ''} (needed by {command})"
    return [None]


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
    suffix = COMMANDS[command].suffix.replace(".{domain}", f".{domain}" if domain else "")
    return (output_dir or log.parent) / (log.name.rsplit(".", 1)[0] + suffix)


def _job(spec: CommandSpec, log: Path, domain, options: BatchOptions, extra: dict, problem: str = "") -> Job:
    out = output_path(spec.name, log, options.output_dir, domain)
    rest = options.extra
    if spec.name == "predict":
        argv = ("predict", str(options.model), str(log), "-o", str(out))
        inputs = (log, options.model)
    else:
        argv = (spec.name, str(log), "-o", str(out))
        inputs = (log,)
    if spec.name == "diagnose" and domain is not None:
        rest = _without_option(rest, "--domain")
        argv += ("--domain", str(domain))
    if spec.name == "pneumatic-fit" and not extra.get("chamber") and not extra.get("all_chambers"):
        argv += ("--all",)
    argv += (*rest, "--quiet")
    stamp = out / "sgp.yaml" if spec.directory else out
    fresh = not options.force and not problem and _newer(stamp, inputs)
    return Job(spec.name, log, out, argv, inputs, domain, fresh, problem)


def _newer(output: Path, inputs) -> bool:
    """Whether ``output`` exists and is at least as new as every input (make's rule)."""
    try:
        t = output.stat().st_mtime
        return all(t >= Path(i).stat().st_mtime for i in inputs)
    except OSError:
        return False


# ----------------------------------------------------------------------------- parsing
@functools.cache
def _parser(command: str):
    """The click command of ``command`` (built once per process)."""
    from diegocal.cli.app import click_command

    return click_command((command,))


def _parse(command: str, argv: Sequence[str]) -> dict:
    """``argv`` (after the command's name) parsed by the command's own parser, as the command line
    parses it: the parameters by name. Raises OptionError for a usage error, DiegocalError for bad
    input an option's check finds (an output folder that does not exist)."""
    import typer

    try:
        with _parser(command).make_context(f"diegocal {command}", list(argv)) as ctx:
            return dict(ctx.params)
    except typer.TyperException as exc:  # click's usage errors
        raise OptionError(f"{command} {shlex.join(argv)}: {' '.join(exc.format_message().split())}") from None


def job_args(job: Job):
    """The job's options: its arguments parsed by the command's parser into the command's options
    dataclass (:class:`diegocal.cli.stac_cmd.StacArgs`, ...). Raises OptionError or DiegocalError."""
    spec = COMMANDS[job.command]
    return getattr(importlib.import_module(spec.module), spec.args)(**_parse(job.command, job.argv[1:]))


# ----------------------------------------------------------------------------- running
def run_job(job: Job, args=None) -> Outcome:
    """Run one job in this process (``args``: :func:`job_args`, parsed here when None); never raises
    (a failure is an Outcome carrying the exception's message). An up-to-date job is not run, but
    its output is checked as a fresh one is."""
    from diegocal.cli.common import collected_warnings, error_message

    if job.problem:
        return Outcome(job, "failed", 0.0, job.problem)
    spec = COMMANDS[job.command]
    module = importlib.import_module(spec.module)
    start, warnings, status = time.perf_counter(), (), "up to date"
    try:
        args = job_args(job) if args is None else args
        if not job.up_to_date:
            with collected_warnings() as logged:
                result = getattr(module, spec.run)(args, command_line(job))
            warnings, status = (*logged, *getattr(result, "warnings", ())), "done"
        why = getattr(module, spec.verdict)(args) if spec.verdict else None
    except (Exception, KeyboardInterrupt) as exc:  # noqa: BLE001 - one job's failure, never the batch's
        return Outcome(job, "failed", time.perf_counter() - start, error_message(exc), warnings=warnings)
    seconds = time.perf_counter() - start if status == "done" else 0.0
    if why is not None:
        return Outcome(job, "failed", seconds, why, judged=True, warnings=warnings)
    return Outcome(job, status, seconds, warnings=warnings)


def run_batch(
    jobs: Sequence[Job],
    jobs_n: int = 1,
    scheduler: str | None = None,
    progress: Callable[[Outcome, int, int], None] | None = None,
) -> list[Outcome]:
    """Run the jobs: ``jobs_n`` at a time in worker processes on this machine, or on the Dask
    cluster at ``scheduler``. Every job's arguments are parsed first, so a usage error (OptionError)
    or an output folder that does not exist (DiegocalError) stops the batch before any job runs.

    Returns one Outcome per job, in the jobs' order; ``progress(outcome, done, total)`` is called
    as each job that is not up to date finishes. Raises DiegocalError when the scheduler cannot be
    reached.
    """
    parsed = [None if j.problem else job_args(j) for j in jobs]
    outcomes: dict[int, Outcome] = {}
    total = sum(not j.up_to_date for j in jobs)

    def record(i: int, outcome: Outcome) -> None:
        outcomes[i] = outcome
        if progress is not None and not jobs[i].up_to_date:
            progress(outcome, sum(not jobs[k].up_to_date for k in outcomes), total)

    todo = []
    for i, (job, args) in enumerate(zip(jobs, parsed, strict=True)):
        if job.up_to_date or job.problem:  # nothing to run: checked here
            record(i, run_job(job, args))
        else:
            todo.append((i, job, args))
    if todo and scheduler:
        _run_dask(todo, scheduler, record)
    elif todo:
        _run_local(todo, jobs_n, record)
    return [outcomes[i] for i in range(len(jobs))]


def _one_blas_thread() -> None:
    """Worker initializer when several jobs share the machine: one BLAS thread each, unless the user
    chose otherwise (set before the worker imports numpy)."""
    for var in THREAD_VARS:
        os.environ.setdefault(var, "1")


def _run_local(todo, jobs_n: int, record) -> None:
    """The jobs in a pool of ``jobs_n`` worker processes (spawned: a fresh interpreter each). A job
    whose process dies fails alone: after a death the jobs that were in flight are run again one at
    a time, so that the one that kills its process is the one that fails."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor, as_completed
    from concurrent.futures.process import BrokenProcessPool

    def pool(n: int) -> ProcessPoolExecutor:
        init = _one_blas_thread if jobs_n > 1 else None
        return ProcessPoolExecutor(n, mp_context=multiprocessing.get_context("spawn"), initializer=init)

    again = []
    with pool(max(1, min(jobs_n, len(todo)))) as workers:
        futures = {workers.submit(run_job, job, args): (i, job, args) for i, job, args in todo}
        for fut in as_completed(futures):
            try:
                record(futures[fut][0], fut.result())
            except BrokenProcessPool:
                again.append(futures[fut])
    workers = None
    for i, job, args in sorted(again, key=lambda t: t[0]):
        workers = workers or pool(1)
        try:
            record(i, workers.submit(run_job, job, args).result())
        except BrokenProcessPool:
            record(i, Outcome(job, "failed", 0.0, DIED))
            workers.shutdown()
            workers = None
    if workers is not None:
        workers.shutdown()


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
        futures = {client.submit(run_job, job, args, pure=False): (i, job) for i, job, args in todo}
        for fut in as_completed(list(futures)):
            i, job = futures[fut]
            try:
                outcome = fut.result()
            except Exception as exc:  # noqa: BLE001 - a lost worker fails its job, not the batch
                outcome = Outcome(job, "failed", 0.0, f"Dask task failed: {type(exc).__name__}: {exc}")
            record(i, outcome)


def command_line(job: Job) -> str:
    """The job as the user would type it."""
    return "diegocal " + " ".join(shlex.quote(a) for a in job.argv)
