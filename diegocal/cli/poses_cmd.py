"""`diegocal poses CANDIDATES -n N`: the next N static poses to record for ``stac --geometry``,
chosen among candidate poses (:mod:`diegocal.stac.geometry_design`): by default those that make
the calibrated model's predictions of the markers most precise over the candidates (I-optimal),
with ``--criterion D`` those that make its parameters' confidence region smallest (D-optimal).

CANDIDATES is a log whose samples are candidate poses: joint angles in a ``q`` stream (rad), or
encoder/pot readings in ``pots`` (turned into angles with ``--calibration`` or sensors.yaml's
gains and biases). ``--recorded LOG`` gives the poses already recorded (a static-pose log, its
pots read the same way), so the new ones complete them. With ``--calibration`` (a STAC
calibration), the poses are weighed by its noise model (marker and pot noise). The chosen samples
are written as a log (every stream of CANDIDATES at those samples), best first: the first k of
them are themselves a good choice of k.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Annotated

import typer

from diegocal.cli.app import app
from diegocal.cli.common import RobotOfLog, cli_errors, default_output, distinct_output, log_output, summary
from diegocal.errors import MissingStreamError

#: Random subsets of the same size the summary compares the choice with.
RANDOM_DRAWS = 20


@dataclass(frozen=True)
class PosesArgs:
    """`diegocal poses`' options, parsed once."""

    candidates: Path
    n: int
    robot: str | None
    calibration: Path | None
    recorded: Path | None
    criterion: str
    output: Path | None
    seed: int
    quiet: bool

    def __post_init__(self):
        distinct_output((self.out,), (self.candidates, self.calibration, self.recorded, self.robot))

    @property
    def out(self) -> Path:
        return self.output or default_output(self.candidates, ".poses.h5")


@dataclass(frozen=True)
class PosesRun:
    """What :func:`run_poses` chose: candidate indices (in order), the identifiable parameters, and
    for the choice and the median over random subsets of the same size: the mean variance of a
    marker coordinate's prediction over the candidates (in units of the marker noise's variance),
    the log det of the parameters' information and their mean standard error (unit noise, scaled
    parameters)."""

    chosen: object
    n_candidates: int
    parameters: int
    variance: float
    random_variance: float
    log_det: float
    random_log_det: float
    stderr: float
    random_stderr: float
    output: Path


def _angles(data, robot, cal):
    """Joint angles (T, n) of a log's samples: its q stream, else its pots through ``cal``."""
    import numpy as np

    if data.has("q"):
        st = data.stream("q")
        q = np.tile(robot.neutral(), (data.n_samples, 1))
        for i, name in enumerate(st.names):
            if name in robot.joint_names:
                q[:, robot.joint_index(name)] = st.data[:, i]
        return q
    if not data.has("pots"):
        raise MissingStreamError("poses needs candidate joint angles: a 'q' stream, or encoder readings in 'pots'")
    from diegocal.stac.pot_inverse import joint_angles_from_pots

    st = data.stream("pots")
    p = np.zeros((data.n_samples, len(cal.pot_names)))
    for i, name in enumerate(cal.pot_names):
        if name in st.names:
            p[:, i] = st.data[:, st.names.index(name)]
    return joint_angles_from_pots(robot, cal, p).q


def run_poses(args: PosesArgs) -> PosesRun:
    """Load the candidates, choose (:func:`diegocal.stac.geometry_design.select_poses`), write them.
    Raises DiegocalError; prints nothing."""
    import numpy as np

    from diegocal.io import load_log, load_yaml, save_log
    from diegocal.robot.resolve import robot_for_log
    from diegocal.stac.calibration import Calibration
    from diegocal.stac.geometry_design import pose_design, select_poses

    data = load_log(args.candidates)
    robot = robot_for_log(args.robot, data)
    cal = Calibration.from_dict(load_yaml(args.calibration), str(args.calibration)) if args.calibration else None
    cal = cal or Calibration.nominal(robot)
    q = _angles(data, robot, cal)
    done = np.zeros((0, robot.n_joints))
    if args.recorded is not None:
        done = _angles(load_log(args.recorded), robot, cal)
    design = pose_design(robot, cal, np.vstack([done, q]))
    recorded = np.arange(len(done))
    chosen = select_poses(design, args.n, recorded, criterion=args.criterion) - len(done)
    rng = np.random.default_rng(args.seed)
    draws = [np.r_[recorded, len(done) + rng.choice(len(q), args.n, replace=False)] for _ in range(RANDOM_DRAWS)]
    mine = np.r_[recorded, len(done) + chosen]
    save_log(_in_order(data, chosen), args.out)
    return PosesRun(
        chosen,
        len(q),
        len(design.names),
        design.prediction_variance(mine),
        float(np.median([design.prediction_variance(d) for d in draws])),
        design.log_det(mine),
        float(np.median([design.log_det(d) for d in draws])),
        float(design.stderr(mine).mean()),
        float(np.median([design.stderr(d).mean() for d in draws])),
        args.out,
    )


def _in_order(data, chosen):
    """The samples ``chosen`` of a log, in the order chosen, 1 s apart (one sample per pose)."""
    from dataclasses import replace

    import numpy as np

    from diegocal.io import Stream
    from diegocal.stac.static import take

    ordered = np.sort(chosen)
    rows = np.searchsorted(ordered, chosen)
    out = take(data, ordered)
    streams = {k: Stream(s.names, s.data[rows]) for k, s in out.streams.items()}
    return replace(out, time=np.arange(len(chosen), dtype=float), streams=streams)


def _criterion(value: str) -> str:
    """Callback of --criterion: I or D (else a usage error, exit 2)."""
    if value.upper() not in ("I", "D"):
        raise typer.BadParameter(f"{value!r} is not one of I, D")
    return value.upper()


@app.command("poses")
@cli_errors
def poses(
    ctx: typer.Context,
    candidates: Annotated[
        Path, typer.Argument(help="Log of candidate poses: joint angles in 'q' (rad) or encoder readings in 'pots'.")
    ],
    n: Annotated[int, typer.Option("-n", min=1, help="How many poses to propose.")] = 30,
    robot: RobotOfLog = None,
    calibration: Annotated[
        Path | None,
        typer.Option(
            help="calib.yaml whose gains, biases and markers to use, and whose marker and pot noise weigh "
            "the poses (default: sensors.yaml's, marker noise alone)."
        ),
    ] = None,
    recorded: Annotated[
        Path | None,
        typer.Option(help="Static-pose log already recorded: the new poses complete it."),
    ] = None,
    criterion: Annotated[
        str,
        typer.Option(
            callback=_criterion,
            help="I: the markers' predictions most precise over the candidates (what held-out poses judge); "
            "D: the parameters' confidence region smallest (log det of their information, FIGAROH's).",
        ),
    ] = "I",
    output: Annotated[
        Path | None,
        typer.Option(
            "-o",
            "--output",
            callback=log_output,
            help="Log of the chosen poses, best first (its first k are a good choice of k); by default "
            "CANDIDATES.poses.h5.",
        ),
    ] = None,
    seed: Annotated[int, typer.Option(help="Seed of the random subsets the choice is compared with.")] = 0,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No summary table.")] = False,
) -> None:
    """Propose the next N static poses for stac --geometry among candidate poses: I-optimal (the
    markers' predictions most precise) by default, D-optimal with --criterion D."""
    args = PosesArgs(**ctx.params)
    done = run_poses(args)
    summary(
        f"poses {Path(args.candidates).name}",
        [
            ("candidates", done.n_candidates),
            (f"chosen ({args.criterion}-optimal, greedy + exchange)", len(done.chosen)),
            ("identifiable parameters", done.parameters),
            (
                "mean prediction variance, σ_m²: chosen / random (median)",
                f"{done.variance:.3g} / {done.random_variance:.3g}",
            ),
            ("log det information: chosen / random (median)", f"{done.log_det:.1f} / {done.random_log_det:.1f}"),
            ("mean standard error: chosen / random (median)", f"{done.stderr:.3g} / {done.random_stderr:.3g}"),
            ("poses", str(done.output)),
        ],
        quiet=args.quiet,
    )
