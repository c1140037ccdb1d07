"""`diegocal stac LOG` (thesis ch. 2): parse → :func:`run_stac` (load → :func:`diegocal.api.calibrate`
→ save calib.yaml) → summary.

A fit that stopped before it converged is written (``fit: converged: false``), said in words, and
exits 1 unless ``--allow-unconverged``; :func:`unconverged` is the one judgement, which ``batch``
applies to the calib.yaml a job wrote.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Literal

import typer

from diegocal.cli.app import app
from diegocal.cli.choices import STAC_LOSSES, STAC_MAX_ITERATIONS, STAC_METHODS, STAC_SCHEDULES
from diegocal.cli.common import (
    RobotOfLog,
    cli_errors,
    command_line,
    default_output,
    distinct_output,
    errors,
    log_output,
    output_path,
    progress_enabled,
    refuse_unconverged,
    summary,
    warn,
)
from diegocal.errors import OptionError

if TYPE_CHECKING:
    from diegocal.robot import Robot
    from diegocal.stac.calibration import Calibration
    from diegocal.stac.pose_cv import PoseCV
    from diegocal.stac.result import StacOptions


@dataclass(frozen=True)
class StacArgs:
    """`diegocal stac`'s options, parsed once: the command's parameters by name (``ctx.params``)."""

    log: Path
    robot: str | None
    output: Path | None
    method: str
    loss: str
    max_iterations: int
    schedule: str
    jobs: int
    seed: int
    joint_angles: Path | None
    cv: bool
    allow_unconverged: bool
    quiet: bool
    geometry: bool = False

    def __post_init__(self):
        distinct_output((self.out, self.joint_angles), (self.log, self.robot), apart=True)
        if self.cv and self.method != "stac":
            raise OptionError("--cv is for --method stac")
        if self.geometry and self.method != "stac":
            raise OptionError("--geometry is for --method stac")
        if self.geometry and self.joint_angles is not None:
            raise OptionError(
                "--geometry fits static poses: there are no tracked joint angles to write (the angles are the pots')"
            )

    @property
    def out(self) -> Path:
        """calib.yaml: ``-o``, by default LOG.calib.yaml beside the log."""
        return self.output or default_output(self.log, ".calib.yaml")

    def options(self) -> StacOptions:
        from diegocal.stac.result import StacOptions

        return StacOptions(
            max_iterations=self.max_iterations,
            loss=self.loss,
            jobs=self.jobs,
            seed=self.seed,
            quiet=self.quiet,
            schedule=self.schedule,
            on_iteration=None if self.quiet else _iteration_lines(),
        )


@dataclass(frozen=True)
class StacRun:
    """What :func:`run_stac` did: the calibration as written, and what the summary says of it.

    robot : the robot it was fitted with; time : (T,) s the log's sample times; pose_cv : the
    leave-one-pose-out evaluation (``--cv``) or None; warnings : lines for the user; markers_seen :
    how many of sensors.yaml's markers the log has a channel of (the others keep their nominal
    positions)."""

    calibration: Calibration
    robot: Robot
    time: object
    output: Path
    joint_angles: Path | None
    pose_cv: PoseCV | None
    warnings: tuple[str, ...]
    geometry: dict | None = None
    markers_seen: int | None = None


def run_stac(args: StacArgs, command: str = "diegocal stac", progress=None) -> StacRun:
    """Load the log and its robot, calibrate (:func:`diegocal.api.calibrate`), write calib.yaml (and
    the joint angles with ``--joint-angles``). Raises DiegocalError; prints nothing.

    ``command`` is recorded in calib.yaml's header; ``progress(k, K)`` is called by ``--cv``."""
    # the library is imported when the command runs, so that `--help` answers at once
    from dataclasses import replace

    from diegocal.api import calibrate
    from diegocal.io import Log, load_log, make_stream, save_log, save_yaml
    from diegocal.io.bundle import header
    from diegocal.robot.resolve import robot_for_log

    data = load_log(args.log)
    robot = robot_for_log(args.robot, data)
    options = args.options()
    geometry = None
    if args.geometry:  # STAC, then the link geometry on the same static poses (issue #34)
        from diegocal.stac.geometry import calibrate_geometry, geometry_calibration
        from diegocal.stac.geometry_cv import pose_folds

        fit = calibrate_geometry(data.without_truth(), robot, options)
        geometry = fit.to_dict()
        cal = replace(fit.calibration, header=header("kinematics", robot, args.log, command))
    else:
        result = calibrate(data.without_truth(), robot, args.method, options)
        cal = replace(result.calibration, header=header("kinematics", robot, args.log, command))
    mapping = cal.to_dict()
    pose_cv = None
    if geometry is not None:
        mapping["geometry"] = geometry
        if args.cv:
            pose_cv = pose_folds(data, robot, geometry_calibration, options, progress=progress)
            mapping["cv"] = pose_cv.to_dict()
    elif args.cv:
        from diegocal.stac.pose_cv import leave_one_pose_out

        pose_cv = leave_one_pose_out(data.without_truth(), robot, options, progress=progress)
        mapping["cv"] = pose_cv.to_dict()
    if args.joint_angles is not None:
        mapping["meta"] = {"joint_angles": str(args.joint_angles.resolve())}
    save_yaml(mapping, args.out)
    if args.joint_angles is not None:  # only on request: a side file beside the logs would be taken for one
        streams = {"q": make_stream(robot.joint_names, result.q)}
        save_log(Log(data.time, streams, robot=data.robot, rate_hz=data.rate_hz), args.joint_angles)
    logged = set(data.streams["markers"].names) if data.has("markers") else set()
    seen = sum(n in logged for n in robot.sensors.marker_names)
    return StacRun(
        cal, robot, data.time, args.out, args.joint_angles, pose_cv, _warnings(cal, data.time, args.out), geometry, seen
    )


def _warnings(cal: Calibration, time, out: Path) -> tuple[str, ...]:
    lines = []
    if cal.rejected:
        times = ", ".join(f"{time[f]:.4g}" for f in cal.rejected[:8]) + (", ..." if len(cal.rejected) > 8 else "")
        lines.append(
            f"the markers of {len(cal.rejected)} frame(s) disagree with their pots (t = {times} s): written off "
            f"as another pose's (listed under 'rejected' in {out})"
        )
    if cal.rejected_poses:
        times = ", ".join(f"{time[r['frame']]:.4g}" for r in cal.rejected_poses[:8])
        more = ", ..." if len(cal.rejected_poses) > 8 else ""
        lines.append(
            f"the markers of {len(cal.rejected_poses)} static pose(s) disagree with the rest beyond their noise "
            f"(starting at t = {times}{more} s): another pose's markers? written off (listed under "
            f"'rejected_poses' in {out})"
        )
    if cal.unobservable:
        names = "; ".join(f"{u['pot']} ({u.get('reason', 'not determined by this log')})" for u in cal.unobservable)
        lines.append(
            f"{len(cal.unobservable)} pot(s) unobservable: {names}; their gain and bias keep their nominal values "
            f"(listed under 'unobservable' in {out})"
        )
    if cal.sigma_unresolved:
        names = ", ".join(u["group"] for u in cal.sigma_unresolved)
        lines.append(
            f"σ {names}: not resolved by this log (the other sensors cannot tell its noise apart from zero), "
            f"held at its detection limit (listed under sigma: unresolved in {out})"
        )
    return tuple(lines)


def unconverged(cal: Calibration) -> str | None:
    """Why ``cal`` is not a converged fit, in words; None when it converged (or its method does not
    iterate: nominal)."""
    if cal.fit.converged or cal.method == "nominal":
        return None
    return f"the {cal.method} fit did not converge: it stopped after {cal.fit.iterations} iteration(s)"


#: What to do about an unconverged fit (said with :func:`unconverged` when it fails the command).
UNCONVERGED_HINT = "raise --max-iterations or check the log, or pass --allow-unconverged to accept it"


def written_verdict(args: StacArgs) -> str | None:
    """:func:`unconverged` of the calib.yaml a run wrote (batch's check of a job's output)."""
    if args.allow_unconverged:
        return None
    from diegocal.io import load_yaml
    from diegocal.stac.calibration import Calibration

    why = unconverged(Calibration.from_dict(load_yaml(args.out), str(args.out)))
    return None if why is None else f"{why} (converged: false in {args.out}); {UNCONVERGED_HINT}"


@app.command("stac")
@cli_errors
def stac(
    ctx: typer.Context,
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
        int,
        typer.Option(
            "--max-iterations",
            min=1,
            help="Safety cap on the alternations of the q- and p-phases (the fit ends when it converges).",
        ),
    ] = STAC_MAX_ITERATIONS,
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
            "from its pots (leave-one-pose-out; a pose starts where a pot moves by more than 6√2 times its noise).",
        ),
    ] = False,
    allow_unconverged: Annotated[
        bool,
        typer.Option(
            "--allow-unconverged",
            help="Exit 0 when the fit stops before it converges (it is written with converged: false and "
            "a warning either way; without this flag the exit status is 1).",
        ),
    ] = False,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No progress bar and no summary table.")] = False,
    geometry: Annotated[
        bool,
        typer.Option(
            "--geometry",
            help="Static poses: also fit each joint's origin and axis (6 parameters per joint, reduced to those "
            "the poses identify; written as joint_geometry terms that predict uses). With --cv: ten contiguous "
            "pose folds.",
        ),
    ] = False,
) -> None:
    """Calibrate pots, markers and the mocap frame; track joint angles (thesis ch. 2)."""
    args = StacArgs(**ctx.params)
    done = run_stac(args, command_line("diegocal stac"), progress=_progress("leave-one-pose-out", args.quiet))
    for line in done.warnings:
        warn(line)
    _summary(done, args)
    why = unconverged(done.calibration)
    late = () if why is None else (f"{why}; it is written with converged: false",)
    refuse_unconverged(late, args.allow_unconverged, UNCONVERGED_HINT)


def _summary(done: StacRun, args: StacArgs) -> None:
    """The summary table. With ``--geometry`` the pots calibrated and the noise levels are the
    geometry fit's (calib.yaml's ``geometry``), and STAC's iterations, cost and time are labelled as
    its start's: STAC's σ per sensor type was fitted with the URDF's geometry, whose error it
    absorbs."""
    from diegocal.stac.calibration import READING_UNITS

    cal, g = done.calibration, done.geometry
    stac = "" if g is None else " (STAC, the start)"
    pots = len(cal.calibrated_pots) if g is None else len(g["pots"])
    rows = [
        ("method", cal.method),
        ("frames", len(done.time)),
        ("pots calibrated" + ("" if g is None else " (geometry fit)"), f"{pots} of {len(cal.pot_names)}"),
        ("markers", _markers_seen(done.markers_seen, len(cal.marker_names))),
        ("iterations" + stac, cal.fit.iterations),
        ("converged" + stac, str(cal.fit.converged)),
    ]
    label = cost_label(args.method, args.loss)
    if label is not None:
        rows.append((label + stac, cal.fit.cost))
    rows.append(("seconds" + stac, cal.fit.seconds))
    if g is None:
        rows += [(f"σ {k} ({READING_UNITS.get(k, 'sensor unit')})", v) for k, v in cal.sigma_by_group.items()]
    else:
        rows += [
            ("σ markers (m), geometry fit", g["sigma_markers"]),
            ("σ pots (sensor unit), geometry fit", g["sigma_pots"]),
        ]
    rows += coverage_rows(cal, done.robot)
    if cal.rejected:
        rows.append(("frames written off (markers)", len(cal.rejected)))
    if cal.rejected_poses:
        rows.append(("poses written off (markers)", len(cal.rejected_poses)))
    if g is not None:
        rows.append(
            (
                "geometry: identifiable parameters",
                f"{g['identifiable']} of {g['parameters']} "
                f"({len(g['dropped'])} dropped: listed under geometry: dropped)",
            )
        )
        rows.append(("geometry: condition number", f"{g['condition']:.3g}"))
        rows.append(("geometry: Gauss-Newton steps", g["iterations"]))
    if done.pose_cv is not None:
        rows += cv_rows(done.pose_cv)
    rows.append(("calibration", str(done.output)))
    if done.joint_angles is not None:
        rows.append(("joint angles", str(done.joint_angles)))
    summary(f"stac {Path(args.log).name}", rows, quiet=args.quiet)
    if done.pose_cv is not None:
        _pose_table(done.pose_cv, args.quiet)


def _markers_seen(seen: int | None, total: int) -> str:
    """The summary's markers: how many of sensors.yaml's the log has (the others stay nominal)."""
    return str(total) if seen is None else f"{seen} of {total} seen"


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


def _iteration_lines():
    """STAC's ``on_iteration``: every few seconds, a line on stderr with the iteration and the time
    so far. No time left: the alternation runs until it converges, which no count foretells."""
    from diegocal.progress import EVERY, duration

    start, last = time.monotonic(), [time.monotonic()]

    def step(iteration: int, _calibration) -> None:
        now = time.monotonic()
        if now - last[0] >= EVERY:
            last[0] = now
            errors.print(f"[dim]stac:[/] iteration {iteration}, {duration(now - start)} so far", highlight=False)

    return step


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


def cv_rows(pose_cv: PoseCV) -> list:
    """Summary rows of a leave-one-pose-out evaluation."""
    flagged = pose_cv.outliers()
    folds = getattr(pose_cv, "folds", None)  # stac --geometry: contiguous pose folds (stac/geometry_cv.py)
    rows = [
        (f"poses ({folds} contiguous folds)" if folds else "poses (leave-one-out)", len(pose_cv.pose)),
        ("pose marker error mean / median (mm)", f"{1000 * pose_cv.mean:.3g} / {1000 * pose_cv.median:.3g}"),
    ]
    if len(flagged):
        rows.append(("poses > 5 x median error", ", ".join(str(int(k)) for k in flagged)))
    return rows


def _pose_table(pose_cv: PoseCV, quiet: bool) -> None:
    """The ten poses with the largest leave-one-out error, worst first."""
    import numpy as np

    show = np.argsort(-np.nan_to_num(pose_cv.error, nan=-1.0))[:10]
    flagged = set(pose_cv.outliers().tolist())
    folds = getattr(pose_cv, "folds", None)  # stac --geometry: contiguous pose folds
    cut = f"held-out marker error ({folds} contiguous pose folds)" if folds else "leave-one-pose-out marker error"
    summary(
        f"{cut} (worst first; * above 5 x the median)",
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
