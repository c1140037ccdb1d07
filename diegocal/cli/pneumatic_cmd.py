"""CLI of the pneumatic domain (thesis ch. 4): `pneumatic-fit` (parse → :func:`run_pneumatic`: load →
:class:`diegocal.api.Pneumatic` fit → save → summary), `pneumatic-merge` and `simulate pneumatics`."""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Literal

import typer

from diegocal.cli.app import app, simulate_app
from diegocal.cli.choices import PNEUMATIC_EXPERIMENTS
from diegocal.cli.common import (
    cli_errors,
    command_line,
    default_output,
    distinct_output,
    eta_lines,
    log_output,
    output_path,
    positive,
    refuse_unconverged,
    summary,
    warn,
)
from diegocal.errors import InputFileError, OptionError


@dataclass(frozen=True)
class PneumaticArgs:
    """`diegocal pneumatic-fit`'s options, parsed once: the command's parameters by name (``ctx.params``)."""

    log: Path
    chamber: list[str] | None
    all_chambers: bool
    robot: str | None
    output: Path | None
    jobs: int
    starts: int
    seed: int
    fd_jacobian: bool
    steady_state: Path | None
    quiet: bool
    allow_unconverged: bool = False

    def __post_init__(self):
        distinct_output((self.out,), (self.log, self.steady_state, self.robot))
        if self.all_chambers == bool(self.chamber):
            raise OptionError("name the chambers to fit: --chamber NAME (repeatable) or --all")

    @property
    def out(self) -> Path:
        """pneumatic.yaml: ``-o``, by default LOG.pneumatic.yaml beside the log."""
        return self.output or default_output(self.log, ".pneumatic.yaml")


@dataclass(frozen=True)
class PneumaticRun:
    """What :func:`run_pneumatic` did: ``fits`` chamber -> its fit (rmse, drift_2s), ``skipped``
    chamber -> why it was not fitted, the file written."""

    fits: dict
    skipped: dict
    output: Path


def run_pneumatic(args: PneumaticArgs, command: str = "diegocal pneumatic-fit", progress=None) -> PneumaticRun:
    """Load the log and its robot, fit each chamber (:class:`diegocal.api.Pneumatic`), write
    pneumatic.yaml. Raises DiegocalError (FitError when no chamber could be fitted); prints nothing.
    ``progress``: a factory ``progress(total)`` of the callable told as each chamber finishes."""
    if args.steady_state is not None and not args.steady_state.exists():
        raise InputFileError(f"{args.steady_state}: no such file")
    # the library is imported when the command runs, so that `--help` answers at once
    from diegocal.api import Pneumatic
    from diegocal.io import load_log
    from diegocal.pneumatic.fit import FitOptions
    from diegocal.robot.resolve import robot_for_log

    data = load_log(args.log)
    for stream in ("pressure", "valve", "pots"):  # log-level problems fail the whole command
        data.stream(stream, needed_by="pneumatic-fit")
    robot = robot_for_log(args.robot, data)
    if not robot.sensors.chamber_names:
        raise InputFileError(f"robot {robot.name!r} has no chambers in sensors.yaml")
    options = FitOptions(jacobian="2-point" if args.fd_jacobian else "analytic", starts=args.starts, seed=args.seed)
    chambers = () if args.all_chambers else tuple(dict.fromkeys(args.chamber))
    step = None if progress is None else progress(len(chambers or robot.sensors.chamber_names))
    model = Pneumatic(chambers, options, jobs=args.jobs).fit(data, robot, progress=step)
    meta = {} if args.steady_state is None else {"steady_state_log": str(args.steady_state.resolve())}
    model.save(args.out, log=args.log, command=command, meta=meta)
    return PneumaticRun(model.fits_, model.skipped_, args.out)


#: What to do about a chamber whose fit stopped at its evaluation budget.
UNCONVERGED_HINT = "try more --starts or check the chamber's data, or pass --allow-unconverged to accept it"


def unconverged(converged: dict) -> str | None:
    """In words, the chambers (name -> converged) whose least squares stopped at its evaluation
    budget before its tolerance; None when every one converged."""
    names = [n for n, ok in converged.items() if not ok]
    if not names:
        return None
    return f"the fit of chamber(s) {', '.join(names)} stopped at its evaluation budget before it converged"


def written_verdict(args: PneumaticArgs) -> str | None:
    """:func:`unconverged` of the pneumatic.yaml a run wrote (batch's check of a job's output)."""
    if args.allow_unconverged:
        return None
    from diegocal.io import load_yaml

    chambers = load_yaml(args.out).get("chambers") or {}
    why = unconverged({n: bool(c.get("converged", True)) for n, c in chambers.items()})
    return None if why is None else f"{why} (converged: false in {args.out}); {UNCONVERGED_HINT}"


@app.command("pneumatic-fit")
@cli_errors
def pneumatic_fit(
    ctx: typer.Context,
    log: Annotated[Path, typer.Argument(help="Log with pressure, valve and pots streams (.h5 or .csv).")],
    chamber: Annotated[
        list[str] | None,
        typer.Option("--chamber", "-c", help="Chamber to fit, as sensors.yaml names it (repeatable)."),
    ] = None,
    all_chambers: Annotated[
        bool, typer.Option("--all", help="Fit every chamber of the robot (instead of --chamber).")
    ] = False,
    robot: Annotated[
        str | None,
        typer.Option(
            "--robot",
            help="Robot directory; by default the robot the log names.",
        ),
    ] = None,
    output: Annotated[
        Path | None,
        typer.Option(
            "-o",
            "--output",
            callback=output_path,
            help="Pneumatic model to write (YAML); by default LOG.pneumatic.yaml beside the log.",
        ),
    ] = None,
    jobs: Annotated[int, typer.Option("--jobs", "-j", min=1, help="Chambers fitted at once, in processes.")] = 1,
    starts: Annotated[int, typer.Option(min=1, help="Starting points per chamber (multi-start).")] = 1,
    seed: Annotated[int, typer.Option(help="Seed of the random starting points.")] = 0,
    fd_jacobian: Annotated[
        bool,
        typer.Option("--fd-jacobian", help="Use a finite-difference Jacobian (a reference for the analytic one)."),
    ] = False,
    steady_state: Annotated[
        Path | None,
        typer.Option("--steady-state", help="Locked-cylinder sweep log, kept for the report (Fig. 4.10)."),
    ] = None,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No progress and no summary table.")] = False,
    allow_unconverged: Annotated[
        bool,
        typer.Option(
            "--allow-unconverged",
            help="Exit 0 when a chamber's fit stops at its evaluation budget (it is written with converged: "
            "false and a warning either way; without this flag the exit status is 1).",
        ),
    ] = False,
) -> None:
    """Fit the 9-parameter valve-chamber model (thesis §4.5.3) by next-step least squares."""
    args = PneumaticArgs(**ctx.params)
    progress = functools.partial(eta_lines, "pneumatic-fit: chambers fitted", quiet=args.quiet)
    done = run_pneumatic(args, command_line("diegocal pneumatic-fit"), progress)
    for name, reason in done.skipped.items():
        warn(f"chamber {name} not fitted: {reason}")
    rows = [("chambers fitted", len(done.fits)), ("skipped", len(done.skipped))]
    if len(done.fits) <= 8:
        rows += [(f"{n}: rmse / drift 2 s", f"{f.rmse:.3g} / {f.drift_2s:.1%}") for n, f in done.fits.items()]
    from diegocal.pneumatic.predict import drift_summary

    drift = drift_summary(f.drift_2s for f in done.fits.values())
    rows += [
        ("2-s drift median / max (of Pc-Pr)", f"{drift['median']:.1%} / {drift['max']:.1%}"),
        ("chambers with drift < 4% / < 10%", f"{drift['below 4 %']} / {drift['below 10 %']}"),
        ("written", str(done.output)),
    ]
    summary("pneumatic-fit", rows, quiet=args.quiet)
    why = unconverged({n: f.converged for n, f in done.fits.items()})
    late = () if why is None else (f"{why}; written with converged: false",)
    refuse_unconverged(late, args.allow_unconverged, UNCONVERGED_HINT)


@app.command("pneumatic-merge")
@cli_errors
def pneumatic_merge(
    files: Annotated[list[Path], typer.Argument(help="pneumatic.yaml files to merge.")],
    output: Annotated[
        Path, typer.Option("-o", "--output", callback=output_path, help="Merged pneumatic model to write (YAML).")
    ],
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No summary table.")] = False,
) -> None:
    """Merge per-chamber pneumatic.yaml files (from `make -j`) into one."""
    # the library is imported when the command runs, so that `--help` answers at once
    from diegocal.io import load_yaml, save_yaml
    from diegocal.pneumatic.files import merge_models

    distinct_output((output,), files)
    merged = merge_models([load_yaml(f) for f in files], files)
    save_yaml(merged, output)
    rows = [("files", len(files)), ("chambers", len(merged["chambers"])), ("written", str(output))]
    summary("pneumatic-merge", rows, quiet=quiet)


@simulate_app.command("pneumatics")
@cli_errors
def simulate_pneumatics_cmd(
    output: Annotated[Path, typer.Option("--output", "-o", callback=log_output, help="Log to write (.h5 or .csv).")],
    robot: Annotated[str, typer.Option(help="Robot directory or bundled robot name.")] = "diego",
    duration: Annotated[
        float, typer.Option(callback=positive, help="Length of each session in s (more than 0).")
    ] = 60.0,
    experiment: Annotated[
        Literal[PNEUMATIC_EXPERIMENTS],
        typer.Option(help="dynamic: the robot flails (§4.5.3); steady-state: locked-cylinder sweep (§4.5.2)."),
    ] = "dynamic",
    seed: Annotated[int, typer.Option(help="Random seed; the same seed gives the same file.")] = 0,
    effect: Annotated[
        list[str] | None,
        typer.Option(
            "--effect",
            metavar="NAME[:CHAMBER][=SIZE]",
            help="Pneumatic effect (repeatable), SIZE (unit, default): valve_delay (s, 0.03), "
            "chamber_leak (orifice m², 1e-6), supply_droop (kPa per g/s of supply flow, 100; "
            "channel 'supply': one line shared by all, 1), pressure_offset (kPa, 15). "
            "A random chamber unless named.",
        ),
    ] = None,
    sessions: Annotated[int, typer.Option(min=1, help="Independent sessions, simulated together.")] = 1,
    substeps: Annotated[int, typer.Option(min=1, help="Integration steps per 10 ms tick.")] = 20,
    pressure_noise: Annotated[
        float, typer.Option(min=0.0, help="Standard deviation of the pressure noise (averaged), kPa.")
    ] = 0.3,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No summary table.")] = False,
) -> None:
    """Simulate valve-chamber systems with the thin-plate physics (thesis §4.2), truth in /truth."""
    # the library is imported when the command runs, so that `--help` answers at once
    from diegocal.io import save_log
    from diegocal.robot import load_robot, resolve_robot_dir
    from diegocal.sim.effects import check_effects, parse_effects
    from diegocal.sim.pneumatics import PneumaticSimOptions, simulate_pneumatics

    effects = check_effects(parse_effects(effect), "pneumatics")
    options = PneumaticSimOptions(
        duration=duration,
        experiment=experiment,
        effects=effects,
        seed=seed,
        sessions=sessions,
        substeps=substeps,
        pressure_noise=pressure_noise,
    )
    model = load_robot(resolve_robot_dir(robot, None))
    log = simulate_pneumatics(model, options)
    save_log(log, output)
    p = log.streams["pressure"].data
    rows = [
        ("robot", log.robot),
        ("experiment", experiment),
        ("chambers", p.shape[1]),
        ("samples", log.n_samples),
        ("pressure range (kPa)", f"{p.min():.0f} - {p.max():.0f}"),
    ]
    rows += [(f"effect {e['cause']}", e["channel"]) for e in log.truth.effects]
    rows.append(("written", str(output)))
    summary("simulate pneumatics", rows, quiet=quiet)
