"""`diegocal sgp-fit LOG` (thesis ch. 3): parse → :func:`run_sgp` (load → :class:`diegocal.api.SGP`
fit → save the ``LOG.sgp/`` directory) → summary table (in-sample nMSE per joint, the guard's
choices).
"""

from __future__ import annotations

from contextlib import contextmanager
from dataclasses import dataclass, replace
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Literal

import typer

from diegocal.cli.app import app
from diegocal.cli.choices import (
    FRICTION_KINDS,
    SGP_EXACT_MAX,
    SGP_INFERENCE,
    SGP_INPUT_STREAMS,
    SGP_KINDS,
    SGP_MIN_NOISE,
    SGP_N_INDUCING,
    SGP_RESTARTS,
)
from diegocal.cli.common import (
    RobotOfLog,
    cli_errors,
    comma_list,
    command_line,
    default_output,
    distinct_output,
    errors,
    output_path,
    progress_enabled,
    refuse_unconverged,
    split_words,
    summary,
    warn,
)
from diegocal.errors import OptionError

if TYPE_CHECKING:
    from diegocal.sgp import SGPOptions
    from diegocal.sgp.model import DynamicsModel


@contextmanager
def fit_progress(quiet: bool):
    """A progress bar on stderr for the fit's stages (ML-II starts, cross-validation, posterior);
    yields the ``progress`` callable of :func:`fit_dynamics`, or None with --quiet or no terminal."""
    if not progress_enabled(quiet):
        yield None
        return
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    columns = (
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        TimeRemainingColumn(),  # the time left of the stage (issue #33)
    )
    with Progress(*columns, console=errors, transient=True) as bar:
        tasks = {}

        def update(kind: str, stage: str, done: int, total: int) -> None:
            key = (kind, stage)
            if key not in tasks:
                tasks[key] = bar.add_task(f"{kind}: {stage}", total=total)
            bar.update(tasks[key], completed=done, total=total)

        yield update


@dataclass(frozen=True)
class SgpArgs:
    """`diegocal sgp-fit`'s options, parsed once: the command's parameters by name (``ctx.params``)."""

    log: Path
    robot: str | None
    model: str
    friction: str
    inference: str
    n_inducing: int
    guard: bool
    region: bool
    joint_region: bool | None
    gp_inputs: str | None
    restarts: int
    min_noise: float
    seed: int
    jobs: int
    output: Path | None
    quiet: bool
    max_iterations: int = 200
    allow_unconverged: bool = False

    def __post_init__(self):
        distinct_output((self.out,), (self.log, self.robot))
        if self.joint_region and not self.region:
            raise OptionError("--joint-region needs --region (the joint GP is cut where the two-stage GP is)")

    @property
    def out(self) -> Path:
        """The model directory: ``-o``, by default LOG.sgp/ beside the log."""
        return self.output or default_output(self.log, ".sgp")

    def options(self) -> SGPOptions:
        from diegocal.sgp import SGPOptions
        from diegocal.sgp.model import default_guard

        words = split_words(self.friction)
        opts = SGPOptions(
            kind=self.model,
            friction=() if words == ("none",) else words,
            inference=self.inference,
            n_inducing=self.n_inducing,
            restarts=self.restarts,
            seed=self.seed,
            jobs=self.jobs,
            guard=self.guard,
            gp_inputs=split_words(self.gp_inputs) if self.gp_inputs is not None else None,
            min_noise=self.min_noise,
            maxiter=self.max_iterations,
        )
        joint_region = self.region if self.joint_region is None else self.joint_region
        if not (self.region and joint_region):
            g = default_guard(opts.friction)
            opts = replace(opts, guard_options=replace(g, region=self.region, joint_region=joint_region))
        return opts


def run_sgp(args: SgpArgs, command: str = "diegocal sgp-fit", progress=None) -> DynamicsModel:
    """Load the log and its robot, fit (:class:`diegocal.api.SGP`), write the model directory; the
    fitted model. Raises DiegocalError; prints nothing. ``progress``: see :func:`fit_progress`."""
    # the library is imported when the command runs, so that `--help` answers at once
    from diegocal.api import SGP
    from diegocal.io import load_log
    from diegocal.robot.resolve import robot_for_log

    data = load_log(args.log)
    robot = robot_for_log(args.robot, data)
    fitted = SGP(args.options()).fit(data, robot, progress=progress)
    meta = {"robot": str(robot.directory or robot.name), "created": datetime.now(UTC).isoformat(timespec="seconds")}
    fitted.save(args.out, log=args.log, command=command, meta=meta)
    return fitted.model_


#: What to do about hyperparameter runs stopped by their iteration cap.
UNCONVERGED_HINT = "raise --max-iterations, or pass --allow-unconverged to accept it"


def written_verdict(args: SgpArgs) -> str | None:
    """:func:`~diegocal.sgp.store.unconverged` of the sgp.yaml a run wrote (batch's check of a job's output)."""
    if args.allow_unconverged:
        return None
    from diegocal.sgp.store import load_summary, unconverged

    why = unconverged(load_summary(args.out))
    return None if why is None else f"{why} (converged: false in {args.out}/sgp.yaml); {UNCONVERGED_HINT}"


@app.command("sgp-fit")
@cli_errors
def sgp_fit(
    ctx: typer.Context,
    log: Annotated[Path, typer.Argument(help="Log with q, qd, qdd and tau streams (.h5 or .csv).")],
    robot: RobotOfLog = None,
    model: Annotated[
        Literal[SGP_KINDS],
        typer.Option(
            "--model",
            "-m",
            help="sgp: parametric part (rigid body and friction) and GP learnt jointly (eq. 3.1-3.20); pr: "
            "the parametric part alone (§3.3.3); gp: a GP alone (§3.3.2); prgp: pr, then a GP on its "
            "residuals (§3.4.1).",
        ),
    ] = "sgp",
    friction: Annotated[
        str,
        typer.Option(
            "--friction",
            callback=comma_list(FRICTION_KINDS, "none"),
            help="Friction columns of the parametric part, comma-separated: viscous, coulomb, or none.",
        ),
    ] = "viscous,coulomb",
    inference: Annotated[
        Literal[SGP_INFERENCE],
        typer.Option("--inference", help=f"GP inference; auto is exact up to {SGP_EXACT_MAX} samples, then sparse."),
    ] = "auto",
    n_inducing: Annotated[
        int,
        typer.Option(
            "--n-inducing",
            min=1,
            help="Sparse inference: at most this many inducing inputs per joint (chosen until they "
            "miss at most 1 % of the noise variance).",
        ),
    ] = SGP_N_INDUCING,
    guard: Annotated[bool, typer.Option("--guard/--no-guard", help="SGP guard: keep the GP off the physics.")] = True,
    region: Annotated[
        bool,
        typer.Option(
            "--region/--no-region",
            help="SGP guard: let each joint's two-stage GP be cut at an onset in the joint's angle (a friction "
            "confined to part of the range); the guard's nested cross-validation decides.",
        ),
    ] = True,
    joint_region: Annotated[
        bool | None,
        typer.Option(
            "--joint-region/--no-joint-region",
            help="SGP guard, with --region: where a cut two-stage GP loses, also offer the joint GP cut at the same "
            "onset (W and the GP learnt together; for short runs, where PR's friction is biased). Default: on "
            "with --region.",
            show_default=False,
        ),
    ] = None,
    gp_inputs: Annotated[
        str | None,
        typer.Option(
            "--gp-inputs",
            callback=comma_list(SGP_INPUT_STREAMS),
            help="Streams the GP sees, comma-separated (q, qd, qdd); by default q,qd with the guard, else q,qd,qdd.",
        ),
    ] = None,
    restarts: Annotated[
        int, typer.Option("--restarts", min=0, help="Extra hyperparameter starts of ML-II.")
    ] = SGP_RESTARTS,
    min_noise: Annotated[
        float,
        typer.Option(
            "--min-noise",
            min=0.0,
            help="Floor of the noise std σ_v relative to std(tau) per joint; raise it (e.g. 0.2) for "
            "low-pass filtered torques, whose correlated noise ML-II otherwise fits.",
        ),
    ] = SGP_MIN_NOISE,
    seed: Annotated[int, typer.Option("--seed", help="Seed of the random hyperparameter starts and subsets.")] = 0,
    jobs: Annotated[
        int,
        typer.Option(
            "--jobs",
            "-j",
            min=1,
            help="Threads for independent work (hyperparameter starts, cross-validation folds, "
            "joints), each on one BLAS thread.",
        ),
    ] = 1,
    output: Annotated[
        Path | None,
        typer.Option(
            "-o",
            "--output",
            callback=output_path,
            help="Model directory to write; by default LOG.sgp/ beside the log.",
        ),
    ] = None,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No progress bar and no summary table.")] = False,
    max_iterations: Annotated[
        int, typer.Option("--max-iterations", min=1, help="L-BFGS-B iterations per hyperparameter run (ML-II).")
    ] = 200,
    allow_unconverged: Annotated[
        bool,
        typer.Option(
            "--allow-unconverged",
            help="Exit 0 when a hyperparameter run stops at --max-iterations before its tolerance (the model "
            "is written with converged: false either way).",
        ),
    ] = False,
) -> None:
    """Fit a torque model: parametric (rigid body + friction) part, GP part and hyperparameters."""
    args = SgpArgs(**ctx.params)
    with fit_progress(args.quiet) as progress:
        fitted = run_sgp(args, command_line("diegocal sgp-fit"), progress)
    out = args.out
    rows = [(f"nMSE in-sample {j}", float(v)) for j, v in zip(fitted.joint_names, fitted.nmse_in_sample_, strict=True)]
    par = fitted.parametric_
    rows = [
        ("model", args.model),
        ("samples", len(fitted.U_)),
        ("inference", fitted.gp_.inference),
        ("base parameters", 0 if par is None else len(par.names)),
    ] + rows
    hyper = fitted.hyperparameters_
    rows += [(f"guard {j}", _guard_text(hyper[j])) for j in fitted.joint_names if "guard_choice" in hyper[j]]
    rows += [
        (f"inducing {j}", f"{hyper[j]['n_inducing']} (missed prior variance {hyper[j]['sparse_gap']:.2g} σ_v²)")
        for j in fitted.joint_names
        if "n_inducing" in hyper[j]
    ]
    from diegocal.report.sgp_text import fine_inputs

    rows += [
        (f"fine GP detail {j}", ", ".join(f"{v:.2g} of {k}'s spread" for k, v in fine.items())
         + ": this path's detail or a fine effect; check on another session")
        for j, fine in fine_inputs(hyper).items()
    ]
    if fitted.joints_without_tau:
        rows.append(("not fitted (no tau)", ", ".join(fitted.joints_without_tau)))
    from diegocal.sgp.store import load_summary, prior_held, unconverged

    unknown, held = prior_held(fitted)
    if unknown:
        rows.append(("not identified (null)", _names(unknown)))
        warn(f"the log does not identify {len(unknown)} base parameter(s), written null: {_names(unknown)} "
             "(a joint that never moves has no friction to fit)")
    if held:
        rows.append(("held by the prior", _names(held)))
        warn(f"{len(held)} of {fitted.base_.n_base} base parameters are held by the prior more than by the data "
             f"({_names(held)}): their values are pulled toward 0 and their ± are mostly the prior's; a longer or "
             "richer excitation identifies them")

    why = unconverged(load_summary(out))
    rows.append(("converged", "yes: every fit to its tolerance" if why is None else "no: see below"))
    summary(f"sgp-fit → {out}", rows, quiet=args.quiet)
    late = () if why is None else (f"{why}; written with converged: false",)
    refuse_unconverged(late, args.allow_unconverged, UNCONVERGED_HINT)


def _names(names, n: int = 4) -> str:
    return ", ".join(names[:n]) + (f" and {len(names) - n} more" if len(names) > n else "")


def _guard_text(entry: dict) -> str:
    """The guard's choice for one joint and the cross-validated nMSE of every candidate it
    weighed, lowest first (the choice may not be the lowest: a GP must beat PR by one standard
    error and 2 % of PR's nMSE, two stages the other choice by one standard error)."""
    from diegocal.sgp.store import region_text

    scores = sorted((entry.get("guard_validation") or {}).items(), key=lambda kv: kv[1])
    weighed = ", ".join(f"{label} {value:.3g}" for label, value in scores)
    return entry["guard_choice"] + region_text(entry) + (f" (cross-validated nMSE: {weighed})" if weighed else "")
