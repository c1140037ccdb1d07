"""`diegocal stac LOG` (thesis ch. 2) and the calib.yaml predictor of `diegocal predict`."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Literal

import typer

from diegocal.cli.app import app
from diegocal.cli.choices import STAC_LOSSES, STAC_METHODS, STAC_SCHEDULES
from diegocal.cli.common import (
    RobotOfLog,
    cli_errors,
    command_line,
    default_output,
    errors,
    log_output,
    output_path,
    progress_enabled,
    robot_for_log,
    summary,
    usage_error,
    warn,
)
from diegocal.errors import FitError

if TYPE_CHECKING:
    from diegocal.io.log import Log
    from diegocal.robot import Robot
    from diegocal.stac.calibration import Calibration
    from diegocal.stac.result import StacOptions, StacResult

METHODS = STAC_METHODS


def run_method(method: str, log: Log, robot: Robot, options: StacOptions) -> StacResult:
    """Dispatch to the calibration method; each is imported when it runs."""
    from diegocal.stac.calibration import Calibration
    from diegocal.stac.result import StacResult

    if method == "stac":
        from diegocal.stac.stac import calibrate

        return calibrate(log, robot, options)
    if method == "nominal":
        from diegocal.stac.model import Observation
        from diegocal.stac.stac import initial_q

        obs = Observation(log, robot)
        cal = Calibration.nominal(robot)
        return StacResult(cal, initial_q(obs, obs.params_from(cal), options))
    try:
        if method == "classical":
            from diegocal.stac.classical import calibrate_classical

            return calibrate_classical(log, robot, options, nonlinear="constrain")
        if method == "ekf":
            from diegocal.stac.ekf import calibrate_ekf

            return calibrate_ekf(log, robot, options)
    except ImportError:
        raise FitError(f"method {method!r} is not available in this build") from None
    raise FitError(f"unknown method {method!r} (expected one of {', '.join(METHODS)})")


def cost_label(method: str, loss: str) -> str | None:
    """What each method's ``fit.cost`` is, for the summary (None: the method has none)."""
    if method == "stac":
        robust = "" if loss == "linear" else f", markers under the {loss} loss"
        return f"−log-likelihood, eq. 2.5 (nats{robust}; without constants, so it may be < 0)"
    if method == "classical":
        loss_text = "squared marker residuals" if loss == "linear" else f"{loss} ρ of the marker residuals"
        return f"½ Σ {loss_text}, eq. 2.4 (m²)"
    if method == "ekf":
        return "½ Σ νᵀS⁻¹ν, the EKF innovations' normalised squared error"
    return None


@app.command("stac")
@cli_errors
def stac(
    log: Annotated[Path, typer.Argument(help="Log with pots and markers streams (.h5 or .csv).")],
    robot: RobotOfLog = None,
    output: Annotated[
        Path | None,
        typer.Option(
            "-o",
            "--output",
            callback=output_path,
            help="Calibration to write (YAML); by default LOG.calib.yaml beside the log.",
        ),
    ] = None,
    method: Annotated[
        Literal[STAC_METHODS],
        typer.Option(
            metavar="METHOD",
            help="stac: sensors and joint angles together (thesis ch. 2); classical: marker regression "
            "on pot angles (§2.2.1); ekf: extended Kalman filter (§2.4.1); nominal: sensors.yaml as it is.",
        ),
    ] = "stac",
    loss: Annotated[
        Literal[STAC_LOSSES],
        typer.Option(
            help="Marker loss: linear is Gaussian (eq. 2.21); huber and tukey are robust to mocap outliers "
            "and swapped labels."
        ),
    ] = "linear",
    max_iterations: Annotated[
        int, typer.Option("--max-iterations", min=1, help="Most alternations of the q- and p-phases.")
    ] = 50,
    schedule: Annotated[
        Literal[STAC_SCHEDULES],
        typer.Option(help="q-phase schedule (§2.6.1): one LM step per alternation, LM to the end, or BFGS."),
    ] = "lm-iter",
    jobs: Annotated[int, typer.Option("--jobs", "-j", min=1, help="Threads for the q-phase.")] = 1,
    seed: Annotated[int, typer.Option(help="Random seed (STAC itself is deterministic).")] = 0,
    joint_angles: Annotated[
        Path | None,
        typer.Option(
            "--joint-angles",
            callback=log_output,
            help="Also write the tracked joint angles to this log (.h5 or .csv).",
        ),
    ] = None,
    cv: Annotated[
        bool,
        typer.Option(
            "--cv",
            help="Static poses: also calibrate without each pose and print its markers' error predicted "
            "from its pots (leave-one-pose-out; a pose starts where a pot moves by 1 % of its range).",
        ),
    ] = False,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No progress bar and no summary table.")] = False,
) -> None:
    """Calibrate pots, markers and the mocap frame; track joint angles (thesis ch. 2)."""
    if cv and method != "stac":
        raise usage_error("stac", "--cv is for --method stac")
    from dataclasses import replace

    from diegocal.io import load_log, make_stream, save_log, save_yaml
    from diegocal.io.bundle import header
    from diegocal.io.log import Log
    from diegocal.stac.result import StacOptions

    data = load_log(log)
    model = robot_for_log(robot, data)
    options = StacOptions(
        max_iterations=max_iterations,
        loss=loss,
        jobs=jobs,
        seed=seed,
        quiet=quiet,
        schedule=schedule,
    )
    result = run_method(method, data.without_truth(), model, options)
    out = output or default_output(log, ".calib.yaml")
    cal = replace(result.calibration, header=header("calibration", model, log, command_line("diegocal stac")))
    mapping = cal.to_dict()
    pose_cv = None
    if cv:
        from diegocal.stac.static import leave_one_pose_out

        pose_cv = leave_one_pose_out(data, model, options, progress=_progress("leave-one-pose-out", quiet))
        mapping["cv"] = pose_cv.to_dict()
    if joint_angles is not None:
        mapping["meta"] = {"joint_angles": str(joint_angles.resolve())}
    save_yaml(mapping, out)
    if joint_angles is not None:  # only on request: a side file beside the logs would be taken for one
        q_log = Log(data.time, {"q": make_stream(model.joint_names, result.q)}, robot=data.robot, rate_hz=data.rate_hz)
        save_log(q_log, joint_angles)
    if cal.rejected:
        times = ", ".join(f"{data.time[f]:.4g}" for f in cal.rejected[:8]) + (", ..." if len(cal.rejected) > 8 else "")
        warn(
            f"the markers of {len(cal.rejected)} frame(s) disagree with their pots (t = {times} s): written off "
            f"as another pose's (listed under 'rejected' in {out})"
        )
    if cal.unobservable:
        names = ", ".join(u["pot"] for u in cal.unobservable)
        warn(
            f"{len(cal.unobservable)} pot(s) unobservable (no marker moves with their joints): {names}; "
            f"their gain and bias keep their nominal values (listed under 'unobservable' in {out})"
        )
    if cal.sigma_unresolved:
        names = ", ".join(u["group"] for u in cal.sigma_unresolved)
        warn(
            f"σ {names}: not resolved by this log (the other sensors cannot tell its noise apart from zero), "
            f"held at its detection limit (listed under sigma: unresolved in {out})"
        )
    rows = [
        ("method", cal.method),
        ("frames", data.n_samples),
        ("pots", len(cal.pot_names)),
        ("markers", len(cal.marker_names)),
        ("iterations", cal.fit.iterations),
        ("converged", str(cal.fit.converged)),
    ]
    label = cost_label(method, loss)
    if label is not None:
        rows.append((label, cal.fit.cost))
    rows.append(("seconds", cal.fit.seconds))
    rows += [(f"σ {g} ({'m' if g == 'markers' else 'sensor unit'})", v) for g, v in cal.sigma_by_group.items()]
    rows += coverage_rows(cal, model)
    if cal.rejected:
        rows.append(("frames written off (markers)", len(cal.rejected)))
    if pose_cv is not None:
        rows += cv_rows(pose_cv)
    rows += [("calibration", str(out))] + ([("joint angles", str(joint_angles))] if joint_angles else [])
    summary(f"stac {Path(log).name}", rows, quiet=quiet)
    if pose_cv is not None:
        import numpy as np

        show = np.argsort(-np.nan_to_num(pose_cv.error, nan=-1.0))[:10]
        flagged = set(pose_cv.outliers().tolist())
        summary(
            "leave-one-pose-out marker error (worst first; * above 5 x the median)",
            [
                (
                    int(pose_cv.pose[i]),
                    f"{pose_cv.start[i]:.4g}",
                    int(pose_cv.samples[i]),
                    f"{1000 * pose_cv.error[i]:.2f}" + (" *" if pose_cv.pose[i] in flagged else ""),
                )
                for i in show
            ],
            columns=("pose", "start (s)", "samples", "error (mm)"),
            quiet=quiet,
        )


def _progress(label: str, quiet: bool):
    """A ``progress(k, K)`` callback drawing a bar on stderr (None when quiet or not a terminal)."""
    if not progress_enabled(quiet):
        return None
    from rich.progress import Progress

    bar = Progress(console=errors, transient=True)
    task = bar.add_task(label, total=None)

    def step(k: int, total: int) -> None:
        if k == 0:
            bar.start()
        bar.update(task, completed=k, total=total)
        if k == total - 1:
            bar.stop()

    return step


def cv_rows(pose_cv) -> list:
    """Summary rows of a leave-one-pose-out evaluation."""
    flagged = pose_cv.outliers()
    rows = [
        ("poses (leave-one-out)", len(pose_cv.pose)),
        ("pose marker error mean / median (mm)", f"{1000 * pose_cv.mean:.3g} / {1000 * pose_cv.median:.3g}"),
    ]
    if len(flagged):
        rows.append(("poses > 5 x median error", ", ".join(str(int(k)) for k in flagged)))
    return rows


def coverage_rows(cal: Calibration, robot: Robot) -> list:
    """Summary rows: what the data could not determine, and the joints the model locked."""
    rows = []
    if cal.unobservable:
        rows.append(("unobservable (nominal)", ", ".join(u["pot"] for u in cal.unobservable)))
    if cal.gauges:
        rows.append(("gauges (bias nominal)", ", ".join(f"{g['joint']} ({g['pot'] or '-'})" for g in cal.gauges)))
    if robot.locked:
        shown = ", ".join(list(robot.locked)[:4]) + (", ..." if len(robot.locked) > 4 else "")
        rows.append((f"locked joints ({len(robot.locked)})", f"{shown} (at 0 or sensors.yaml's locked)"))
    return rows


#: predict warns when a held-out error is this many times the calibration's own noise level: the
#: log is then most likely not of the session (robot, mocap frame, marker placement) it was fitted on
