"""CLI: `diegocal simulate kinematics` (dynamics and pneumatics attach from their own modules)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from diegocal.cli.app import simulate_app
from diegocal.cli.choices import EFFECTS as VOCABULARY
from diegocal.cli.choices import KINEMATIC_SIZE_UNITS as SIZE_UNITS
from diegocal.cli.common import cli_errors, log_output, summary
from diegocal.errors import OptionError


def parse_direction(text: str) -> tuple[str, tuple[float, float, float]]:
    """``JOINT:DX:DY:DZ`` -> (joint, (x, y, z))."""
    parts = text.rsplit(":", 3)
    try:
        if len(parts) != 4:
            raise ValueError
        return parts[0], (float(parts[1]), float(parts[2]), float(parts[3]))
    except ValueError:
        raise OptionError(f"--direction {text!r}: expected JOINT:DX:DY:DZ, e.g. pip:1:0:0") from None


@simulate_app.command("kinematics")
@cli_errors
def simulate_kinematics_cmd(
    output: Annotated[Path, typer.Option("--output", "-o", callback=log_output, help="Log to write (.h5 or .csv).")],
    robot: Annotated[str, typer.Option(help="Robot directory or bundled robot name.")] = "diego",
    duration: Annotated[float, typer.Option(help="Session length, s (thesis: 250 s).")] = 250.0,
    rate: Annotated[float, typer.Option(help="Sample rate of pots and markers, Hz.")] = 100.0,
    seed: Annotated[int, typer.Option(help="Random seed; the same seed gives the same file.")] = 0,
    robot_seed: Annotated[int | None, typer.Option(
        "--robot-seed", help="Record the robot of the session simulated with this --seed and the same "
        "--duration (its calibration, mocap frame and effects), with this session's own motion and noise: "
        "held-out logs of one robot. Default: --seed.")] = None,
    effect: Annotated[list[str] | None, typer.Option(
        "--effect", metavar="NAME[:CHANNEL][=SIZE]",
        help="Kinematic effect to inject (repeatable); SIZE, when given, is "
        + "; ".join(f"{k} {SIZE_UNITS[k]}" for k, v in VOCABULARY.items() if v == "kinematics")
        + ". Without SIZE: the simulator's physical ranges.")] = None,
    direction: Annotated[list[str] | None, typer.Option(
        "--direction", metavar="JOINT:DX:DY:DZ",
        help="Direction of JOINT's link offset in its parent joint's frame (repeatable); "
        "default random.")] = None,
    occlusion: Annotated[float, typer.Option(help="Fraction of occluded marker samples.")] = 0.1,
    occlusion_run: Annotated[float, typer.Option(help="Mean occlusion length, s.")] = 0.5,
    gain_error: Annotated[float, typer.Option(help="True gain = nominal·(1 + U(±this)).")] = 0.2,
    bias_error: Annotated[float, typer.Option(help="True bias error U(±this) rad · gain.")] = 0.3,
    marker_offset: Annotated[float, typer.Option(
        help="Mean distance of true markers from nominal, m.")] = 0.03,
    pot_noise: Annotated[float, typer.Option(help="Pot noise standard deviation, V.")] = 0.005,
    marker_noise: Annotated[float, typer.Option(help="Marker noise per axis, m.")] = 0.002,
    poses: Annotated[int, typer.Option(
        "--poses", min=0, help="Static poses instead of a moving session (0: moving); --duration, --rate, "
        "--effect and occlusion then do not apply.")] = 0,
    pose_samples: Annotated[int, typer.Option("--pose-samples", min=1, help="Samples per static pose.")] = 1,
    wrong_poses: Annotated[int, typer.Option(
        "--wrong-poses", min=0, help="Static poses filed with another pose's mocap frame.")] = 0,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No summary table.")] = False,
) -> None:
    """Simulate a kinematic calibration session (thesis §2.5.1) with truth in /truth."""
    # the library is imported when the command runs, so that `--help` answers at once
    import numpy as np

    from diegocal.io import save_log
    from diegocal.robot import load_robot, resolve_robot_dir
    from diegocal.sim.effects import check_effects, parse_effects
    from diegocal.sim.kinematics import KinematicsOptions, simulate_kinematics

    if poses:
        return _static_poses(output, robot, seed, poses, pose_samples, wrong_poses, gain_error, bias_error,
                             marker_offset, pot_noise, marker_noise, quiet)
    effects = check_effects(parse_effects(effect), "kinematics")
    options = KinematicsOptions(
        duration=duration, rate_hz=rate, effects=effects, directions=dict(map(parse_direction, direction or ())),
        occlusion=occlusion,
        occlusion_run=occlusion_run, gain_error=gain_error, bias_error=bias_error,
        marker_offset=marker_offset, pot_noise=pot_noise, marker_noise=marker_noise, robot_seed=robot_seed).check()
    model = load_robot(resolve_robot_dir(robot, None))
    log = simulate_kinematics(model, options, np.random.default_rng(seed))
    save_log(log, output)
    rows = [("robot", log.robot), ("samples", log.n_samples), ("duration (s)", log.duration)]
    if log.has("pots"):
        rows.append(("pots", len(log.streams["pots"].names)))
    if log.has("markers"):
        x = log.streams["markers"].data
        rows += [("markers", x.shape[1]),
                 ("occluded fraction", float(np.isnan(x[..., 0]).mean()))]
    for e in log.truth.effects:
        rows.append((f"effect {e['cause']}", e["channel"]))
    rows.append(("written", str(output)))
    summary("simulate kinematics", rows, quiet=quiet)


def _static_poses(output, robot, seed, poses, samples, wrong, gain_error, bias_error, marker_offset, pot_noise,
                  marker_noise, quiet) -> None:
    """`simulate kinematics --poses N`: a static-pose session (sim.static_poses.simulate_static_poses)."""
    import numpy as np

    from diegocal.io import save_log
    from diegocal.robot import load_robot, resolve_robot_dir
    from diegocal.sim.static_poses import StaticPoseOptions, simulate_static_poses

    options = StaticPoseOptions(n_poses=poses, samples=samples, wrong=wrong, gain_error=gain_error,
                                bias_error=bias_error, marker_offset=marker_offset, pot_noise=pot_noise,
                                marker_noise=marker_noise).check()
    model = load_robot(resolve_robot_dir(robot, None))
    log = simulate_static_poses(model, options, np.random.default_rng(seed))
    save_log(log, output)
    rows = [("robot", log.robot), ("poses", poses), ("samples", log.n_samples)]
    for e in log.truth.effects:
        rows.append((f"effect {e['cause']}", f"poses {e['values']['poses']}"))
    rows.append(("written", str(output)))
    summary("simulate kinematics (static poses)", rows, quiet=quiet)
