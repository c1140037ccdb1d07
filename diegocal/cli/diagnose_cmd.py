"""`diegocal diagnose LOG`: what the model gets wrong, the named cause, the extended model, the gain.

parse → :func:`run_diagnose` (load the log and robot → :func:`diegocal.api.diagnose` per domain →
write the extended model, a bundle `predict` accepts, and diagnosis.yaml) → summary table.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer
from rich.markup import escape

from diegocal.cli.app import app
from diegocal.cli.common import (
    cli_errors,
    command_line,
    default_output,
    distinct_output,
    errors,
    output_path,
    refuse_unconverged,
    split_words,
    summary,
)
from diegocal.domains import DOMAIN_NAMES
from diegocal.domains import domain as domain_record
from diegocal.errors import MissingStreamError

if TYPE_CHECKING:
    from diegocal.diagnose import DiagnoseOptions


def _friction(text: str) -> str:
    """Parse-time check of --friction (a bad value is a usage error, exit 2)."""
    parts = tuple(t.strip() for t in text.split(",") if t.strip())
    bad = [p for p in parts if p not in ("viscous", "coulomb", "none")]
    if bad:
        raise typer.BadParameter(f"unknown friction kind(s) {', '.join(bad)}; use viscous,coulomb or none")
    return text


def _domain(text: str | None) -> str | None:
    """Parse-time check of --domain."""
    if text is not None and text not in DOMAIN_NAMES:
        raise typer.BadParameter(f"{text!r} is not one of {', '.join(DOMAIN_NAMES)}")
    return text


def _choice(text: str, option: str, allowed: tuple[str, ...]) -> str:
    if text not in allowed:
        raise typer.BadParameter(f"{option} {text!r} is not one of {', '.join(allowed)}")
    return text


def output_paths(log: Path, output: Path | None, domain: str, several: bool) -> tuple[Path, Path]:
    """diagnosis.yaml and the extended model's path for one domain (DESIGN.md: beside the log by
    default, ``<log>.diagnosis.yaml``; with several domains the domain is in the name)."""

    if output is None:
        out = default_output(log, f".{domain}.diagnosis.yaml" if several else ".diagnosis.yaml")
    elif several:
        out = output.with_name(f"{output.name.removesuffix('.yaml')}.{domain}.yaml")
    else:
        out = output
    stem = out.name.removesuffix(".yaml").removesuffix(".diagnosis")
    return out, out.with_name(stem + domain_record(domain).extended_suffix)


@dataclass(frozen=True)
class DiagnoseArgs:
    """`diegocal diagnose`'s options, parsed once: the command's parameters by name (``ctx.params``)."""

    log: Path
    robot: str | None
    domain: str | None
    output: Path | None
    friction: str
    inertia: str
    chamber: list[str] | None
    alpha: float
    min_gain: float
    blocks: int
    jobs: int
    quiet: bool
    allow_unconverged: bool = False

    def __post_init__(self):
        domains = (self.domain,) if self.domain else DOMAIN_NAMES
        paths = [output_paths(self.log, self.output, d, several) for d in domains for several in (False, True)]
        distinct_output([p for pair in paths for p in pair], (self.log, self.robot))

    def options(self, progress=None) -> DiagnoseOptions:
        """The library's options (its ``domain`` is set per domain by :func:`diegocal.api.diagnose`)."""
        from diegocal.diagnose import DiagnoseOptions

        return DiagnoseOptions(
            alpha=self.alpha,
            min_gain=self.min_gain,
            n_blocks=self.blocks,
            friction=tuple(w for w in split_words(self.friction) if w != "none"),
            inertia=self.inertia,
            chambers=tuple(dict.fromkeys(self.chamber or ())),
            jobs=self.jobs,
            progress=progress,
        )


@dataclass(frozen=True)
class Diagnosed:
    """One domain's diagnosis as written: diagnosis.yaml's mapping, its path and the extended model's."""

    domain: str
    mapping: dict
    output: Path
    extended: Path


def run_diagnose(args: DiagnoseArgs, command: str = "diegocal diagnose", progress=None) -> list[Diagnosed]:
    """Load the log and its robot, diagnose each domain (:func:`diegocal.api.diagnose`), write each
    extended model and diagnosis.yaml. Raises DiegocalError; prints nothing. ``progress(text)`` is
    called with each step."""
    # the library is imported when the command runs, so that `--help` answers at once
    from diegocal.api import diagnose
    from diegocal.diagnose import domains_of
    from diegocal.io import load_log, load_yaml
    from diegocal.robot.resolve import robot_for_log

    data = load_log(args.log).without_truth()  # never read here: a simulated log's hidden signals go at once
    todo = (args.domain,) if args.domain else domains_of(data)
    if not todo:
        have = ", ".join(sorted(data.streams)) or "none"
        raise MissingStreamError(
            "nothing to diagnose: the log needs markers + pots (kinematics), q + tau (dynamics) or "
            f"pressure + valve (pneumatics); it has: {have}"
        )
    robot = robot_for_log(args.robot, data)
    done = []
    for domain in todo:
        result = diagnose(data, robot, domain, args.options(progress))[domain]
        out, extended = output_paths(args.log, args.output, domain, len(todo) > 1)
        result.save(out, args.log, command, extended)
        done.append(Diagnosed(domain, load_yaml(out), out, extended))
    return done


#: What to do about a diagnosis whose fits stopped at a cap.
UNCONVERGED_HINT = "its figures are not at their fits' tolerance; pass --allow-unconverged to accept it"


def unconverged(done: Diagnosed) -> str | None:
    """In words, what the written diagnosis says stopped at a cap before its tolerance; None when
    every kept fit converged."""
    if done.mapping.get("converged", True):
        return None
    why = "; ".join(done.mapping.get("unconverged") or ["a fit stopped before it converged"])
    return f"{done.domain} diagnosis: {why} (converged: false in {done.output})"


def written_verdict(args: DiagnoseArgs) -> str | None:
    """:func:`unconverged` of the diagnosis.yaml a run wrote (batch's check of a job's output)."""
    if args.allow_unconverged or args.domain is None:
        return None
    from diegocal.io import load_yaml

    out, extended = output_paths(args.log, args.output, args.domain, False)
    why = unconverged(Diagnosed(args.domain, load_yaml(out), out, extended))
    return None if why is None else f"{why}; {UNCONVERGED_HINT}"


#: What `--jobs` spreads, by domain.
JOBS_HELP = "Parallel workers (pneumatics: a process per chamber; kinematics: threads over frames)."


@app.command("diagnose")
@cli_errors
def diagnose_cmd(
    ctx: typer.Context,
    log: Annotated[Path, typer.Argument(help="Log to diagnose (.h5 or .csv).")],
    robot: Annotated[str | None, typer.Option("--robot", help="Robot directory; by default the log's robot.")] = None,
    domain: Annotated[
        str | None,
        typer.Option(
            "--domain",
            callback=_domain,
            help="kinematics, dynamics or pneumatics; by default every domain the log's streams allow.",
        ),
    ] = None,
    output: Annotated[
        Path | None,
        typer.Option(
            "-o",
            "--output",
            callback=output_path,
            help="diagnosis.yaml to write; by default LOG.diagnosis.yaml beside the log.",
        ),
    ] = None,
    friction: Annotated[
        str,
        typer.Option(
            "--friction", callback=_friction, help="Dynamics: the baseline's friction, viscous,coulomb or none."
        ),
    ] = "viscous,coulomb",
    inertia: Annotated[
        str,
        typer.Option(
            "--inertia",
            callback=lambda v: _choice(v, "--inertia", ("identified", "nominal")),
            help="Dynamics: identified (fit the rigid body) or nominal (keep the URDF's inertias; names a payload).",
        ),
    ] = "identified",
    chamber: Annotated[
        list[str] | None, typer.Option("--chamber", "-c", help="Pneumatics: chamber to diagnose (repeatable).")
    ] = None,
    alpha: Annotated[
        float,
        typer.Option("--alpha", min=1e-6, max=0.5, help="Family-wise false-alarm rate of the whole diagnosis."),
    ] = 0.01,
    min_gain: Annotated[
        float,
        typer.Option(
            "--min-gain",
            min=0.0,
            max=0.99,
            help="Smallest fraction of the mean squared error a finding must remove, on the validation blocks and "
            "again on the held-out ones (0.05: a 2.5 % smaller RMSE).",
        ),
    ] = 0.05,
    blocks: Annotated[
        int,
        typer.Option("--blocks", min=5, help="Contiguous blocks the log is cut into (train / validation / held out)."),
    ] = 10,
    jobs: Annotated[int, typer.Option("--jobs", "-j", min=1, help=JOBS_HELP)] = 1,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No progress and no summary table.")] = False,
    allow_unconverged: Annotated[
        bool,
        typer.Option(
            "--allow-unconverged",
            help="Exit 0 when a kept fit stops at a cap before its tolerance (STAC's iterations, a found term's "
            "refinement, a chamber's budget): written with converged: false and a warning either way.",
        ),
    ] = False,
) -> None:
    """Show what the model gets wrong, name the cause, extend the model and measure the gain on
    held-out blocks of the log."""
    args = DiagnoseArgs(**ctx.params)

    def progress(text: str) -> None:
        errors.print(f"[dim]diagnose:[/] {escape(text)}", highlight=False)

    done = run_diagnose(args, command_line("diegocal diagnose"), None if args.quiet else progress)
    rows = [row for d in done for row in _summary_rows(d)]
    summary(f"diagnose {Path(args.log).name}", rows, quiet=args.quiet)
    late = [why for d in done if (why := unconverged(d)) is not None]
    refuse_unconverged(late, args.allow_unconverged, UNCONVERGED_HINT)


def _summary_rows(done: Diagnosed) -> list:
    from diegocal.diagnose.limits import limits_words
    from diegocal.diagnose.output import pooled_heldout_rmse, shifting_channels, weak_structure

    domain, mapping, out, extended = done.domain, done.mapping, done.output, done.extended
    base = mapping["baseline"]
    pooled = pooled_heldout_rmse(mapping)
    held = [
        (
            f"held-out RMSE baseline → extended{' (' + u + ')' if len(pooled) > 1 else ''}",
            f"{before:.4g} → {after:.4g} {u}",
        )
        for u, (before, after) in pooled.items()
    ]
    rows = [(f"{domain}: baseline", base["model"]), *held]
    declined = [] if mapping["findings"] else mapping.get("declined") or []  # with findings: the runners-up
    shifting = shifting_channels(mapping)
    weak = [] if declined or shifting else weak_structure(mapping)
    found = (
        "none named (see below)" if declined or shifting
        else f"none ({len(weak)} significant binned residual(s), each under the gain a finding needs)" if weak
        else "none (nothing significant)"
    )
    rows.append(("findings", str(len(mapping["findings"])) if mapping["findings"] else found))
    for f in mapping["findings"]:
        where = f"{f['channel']}"
        if f.get("region"):
            r = f["region"]
            where += f" [{r['variable']} {r['low']:.3g}..{r['high']:.3g}]"
        g = f.get("gain") or {}
        if g.get("rmse_before") is not None and g.get("rmse_after") is not None:
            red = g.get("reduction")
            gain = f"{g['rmse_before']:.3g} → {g['rmse_after']:.3g} {f.get('unit', '')}"
            gain += "" if red is None else f" ({red:.0%} less)" if red >= 0 else f" ({-red:.0%} more)"
        else:
            ev = f["evidence"]
            stood = f"; {ev['stand_in']['term']} stood in" if ev.get("stand_in") else ""
            which = "open-loop validation gain" if ev.get("rival") else "validation gain"
            gain = f"{which} {ev.get('validation_gain', 0):.0%} (not explained by any term{stood})"
        ev = f.get("evidence") or {}
        twins = [f"{f['cause']}:{c}" for c in ev.get("indistinguishable_from", [])]
        rivals = ev.get("indistinguishable_causes", []) + twins
        gain += f"; the data cannot tell it from {', '.join(rivals)}" if rivals else ""
        gain += f"; {ev['restated']}" if ev.get("restated") else ""
        rows.append((f"  {f['cause']} on {where}", gain))
    rows += [(f"  declined: {d['cause']} on {d['channel']}", d["why"]) for d in declined]
    rows += [
        (f"  residual shifts in time on {channel}", f"CUSUM p {p:.1g}" + (f" at {t:.3g} s" if t is not None else "")
         + ": structure no term names")
        for channel, p, t in shifting
    ]
    if words := limits_words(mapping.get("detection_limits") or []):
        rows.append(("detection limits (80 % found)", words))
    late = unconverged(done)
    rows.append((f"{domain}: converged", "yes: every kept fit to its tolerance" if late is None else "no: see below"))
    rows += [("diagnosis", str(out)), ("extended model", str(extended))]
    return rows
