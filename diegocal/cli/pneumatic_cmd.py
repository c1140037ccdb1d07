"""CLI of the pneumatic domain (thesis ch. 4): `pneumatic-fit`, `pneumatic-merge`,
`simulate pneumatics` and the ``pneumatic`` predictor of `predict`."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Literal

import typer

from diegocal.cli.app import app, simulate_app
from diegocal.cli.choices import PNEUMATIC_EXPERIMENTS
from diegocal.cli.common import (
    cli_errors,
    command_line,
    default_output,
    errors,
    log_output,
    output_path,
    positive,
    robot_for_log,
    summary,
    usage_error,
)
from diegocal.errors import DiegocalError, FitError, InputFileError


@app.command("pneumatic-fit")
@cli_errors
def pneumatic_fit(
    log: Annotated[Path, typer.Argument(help="Log with pressure, valve and pots streams (.h5 or .csv).")],
    chamber: Annotated[
        list[str] | None,
        typer.Option("--chamber", "-c", help="Chamber to fit, as sensors.yaml names it (repeatable)."),
    ] = None,
    all_chambers: Annotated[
        bool, typer.Option("--all", help="Fit every chamber of the robot (instead of --chamber).")
    ] = False,
    robot: Annotated[
        Path | None,
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
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No summary table.")] = False,
) -> None:
    """Fit the 9-parameter valve-chamber model (thesis §4.5.3) by next-step least squares."""
    if all_chambers == bool(chamber):
        raise usage_error("pneumatic-fit", "name the chambers to fit: --chamber NAME (repeatable) or --all")
    if steady_state is not None and not steady_state.exists():
        raise InputFileError(f"{steady_state}: no such file")
    import numpy as np

    from diegocal.io import load_log, save_yaml
    from diegocal.io.bundle import header
    from diegocal.pneumatic.data import chamber_data
    from diegocal.pneumatic.files import model_dict
    from diegocal.pneumatic.fit import FitOptions, fit_chambers

    data = load_log(log)
    for stream in ("pressure", "valve", "pots"):  # log-level problems fail the whole command
        data.stream(stream, needed_by="pneumatic-fit")
    rob = robot_for_log(robot, data)
    names = list(rob.sensors.chamber_names) if all_chambers else list(dict.fromkeys(chamber))
    if not names:
        raise InputFileError(f"robot {rob.name!r} has no chambers in sensors.yaml")
    datasets, skipped = [], {}
    for name in names:
        try:
            datasets.append(chamber_data(data, rob.sensors, name))
        except DiegocalError as exc:
            if not all_chambers:
                raise
            skipped[name] = str(exc)
    options = FitOptions(jacobian="2-point" if fd_jacobian else "analytic", starts=starts, seed=seed)
    batch = fit_chambers(datasets, options, jobs=jobs)
    batch.skipped.update(skipped)
    for name, reason in batch.skipped.items():
        errors.print(f"[yellow]warning:[/] chamber {name} not fitted: {reason}", highlight=False)
    if not batch.fits:
        first = next(iter(batch.skipped.values()), "no chamber")
        raise FitError(f"no chamber could be fitted ({first})")
    meta = {"log": str(Path(log).resolve()), "robot": str(rob.directory or rob.name)}
    if steady_state is not None:
        meta["steady_state_log"] = str(steady_state.resolve())
    out = output or default_output(log, ".pneumatic.yaml")
    head = header("pneumatic", rob, log, command_line("diegocal pneumatic-fit"))
    save_yaml(model_dict(batch, rob.sensors, options, meta, head), out)
    drifts = np.array([f.drift_2s for f in batch.fits.values()])
    rows = [("chambers fitted", len(batch.fits)), ("skipped", len(batch.skipped))]
    if len(batch.fits) <= 8:
        rows += [(f"{n}: rmse / drift 2 s", f"{f.rmse:.3g} / {f.drift_2s:.1%}") for n, f in batch.fits.items()]
    rows += [
        ("2-s drift median / max (of Pc-Pr)", f"{np.median(drifts):.1%} / {drifts.max():.1%}"),
        ("chambers with drift < 4% / < 10%", f"{(drifts < 0.04).sum()} / {(drifts < 0.10).sum()}"),
        ("written", str(out)),
    ]
    summary("pneumatic-fit", rows, quiet=quiet)


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
    from diegocal.io import load_yaml, save_yaml
    from diegocal.pneumatic.files import merge_models

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
