"""CLI: `diegocal simulate dynamics` — joint torque logs with friction and injected effects."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from diegocal.cli.app import simulate_app
from diegocal.cli.choices import TRAJECTORIES
from diegocal.cli.common import cli_errors, log_output, summary
from diegocal.errors import OptionError


def parse_region(text: str) -> tuple[str, tuple[float, float]]:
    """``JOINT:LOW:HIGH`` (rad) -> (joint, (low, high))."""
    parts = text.rsplit(":", 2)
    try:
        if len(parts) != 3:
            raise ValueError
        return parts[0], (float(parts[1]), float(parts[2]))
    except ValueError:
        raise OptionError(
            f"--region {text!r}: expected JOINT:LOW:HIGH in rad, e.g. theta:2.0:2.5"
        ) from None


@simulate_app.command("dynamics")
@cli_errors
def simulate_dynamics_cmd(
    output: Annotated[Path, typer.Option("--output", "-o", callback=log_output, help="Log to write (.h5 or .csv).")],
    robot: Annotated[str, typer.Option(help="Robot directory or bundled robot name.")] = "arm3",
    duration: Annotated[float, typer.Option(help="Log length, s.")] = 20.0,
    rate: Annotated[float, typer.Option(help="Sample rate, Hz.")] = 100.0,
    seed: Annotated[int, typer.Option(help="Random seed; the same seed gives the same file.")] = 0,
    robot_seed: Annotated[int | None, typer.Option(
        "--robot-seed", help="Record the robot of the session simulated with this --seed (its friction and "
        "effects), with this session's own trajectory and noise: held-out logs of one robot. Default: --seed."
    )] = None,
    trajectory: Annotated[
        str, typer.Option(help=f"One of: {', '.join(TRAJECTORIES)}.")
    ] = "excitation",
    effect: Annotated[
        list[str] | None,
        typer.Option(
            "--effect",
            help="Dynamics effect NAME[:channel][=SIZE] to inject (repeatable): coulomb_friction, "
            "viscous_friction, position_friction, payload (channel: link; SIZE kg), spring, torque_offset, "
            "armature, coupled_friction, stribeck_friction (SIZE the peak above Coulomb), load_friction "
            "(SIZE the coefficient, friction per N·m of the rigid body's torque), torque_lag (SIZE s), torque_gain "
            "(SIZE the relative gain error), transmission_backlash (SIZE the play's half-width, rad, at most 0.1); "
            "other SIZEs in N·m.",
        ),
    ] = None,
    region: Annotated[
        list[str] | None,
        typer.Option(
            "--region", help="Where position_friction acts: JOINT:LOW:HIGH in rad (repeatable)."
        ),
    ] = None,
    noise: Annotated[float, typer.Option(help="Torque noise standard deviation, N·m.")] = 0.01,
    viscous: Annotated[
        float | None,
        typer.Option(
            help="Viscous friction of every joint, N·m·s/rad (default: scaled to the robot)."
        ),
    ] = None,
    coulomb: Annotated[
        float | None,
        typer.Option(help="Coulomb friction of every joint, N·m (default: scaled to the robot)."),
    ] = None,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No summary table.")] = False,
) -> None:
    """Simulate q, qd, qdd, tau of any robot (thesis eq. 3.29 + effects) with truth in /truth."""
    # the library is imported when the command runs, so that `--help` answers at once
    import numpy as np

    from diegocal.io import save_log
    from diegocal.robot import load_robot, resolve_robot_dir
    from diegocal.sim.dynamics import DynamicsOptions, simulate_dynamics
    from diegocal.sim.effects import check_effects, parse_effects

    effects = check_effects(parse_effects(effect), "dynamics")
    regions = dict(parse_region(r) for r in region or ())
    options = DynamicsOptions(
        duration=duration,
        rate_hz=rate,
        trajectory=trajectory,
        effects=effects,
        noise=noise,
        viscous=viscous,
        coulomb=coulomb,
        regions=regions,
        robot_seed=robot_seed,
    )
    model = load_robot(resolve_robot_dir(robot, None))
    for joint in regions:
        model.joint_index(joint)
    log = simulate_dynamics(model, options, np.random.default_rng(seed))
    save_log(log, output)
    tau = log.streams["tau"].data
    rows = [
        ("robot", log.robot),
        ("trajectory", trajectory),
        ("samples", log.n_samples),
        ("duration [s]", log.duration),
    ]
    rows += [
        (f"tau rms {j} [N·m]", float(np.sqrt((tau[:, i] ** 2).mean())))
        for i, j in enumerate(log.streams["tau"].names)
    ]
    for e in log.truth.effects:
        rows.append((f"effect {e['cause']}", e["channel"]))
    rows.append(("written", str(output)))
    summary("simulate dynamics", rows, quiet=quiet)
