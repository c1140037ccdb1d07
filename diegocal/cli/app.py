"""The Typer application and its sub-apps; command modules attach themselves to these."""

import sys

import typer
from typer.core import TyperGroup


class OneLineErrors(TyperGroup):
    """Usage errors (a bad option value, a missing argument) as one line on stderr, exit 2,
    like every other bad input (STYLE.md), instead of the multi-line usage box."""

    def main(self, args=None, prog_name=None, standalone_mode=True, **extra):
        if not standalone_mode:
            return super().main(args, prog_name, standalone_mode=False, **extra)
        try:
            rv = super().main(args, prog_name, standalone_mode=False, **extra)
        except typer.TyperException as exc:  # Click's ClickException and its usage errors
            ctx = getattr(exc, "ctx", None)
            if type(exc).__name__ == "NoArgsIsHelpError":  # `diegocal` alone: the help
                typer.echo(exc.format_message())
                sys.exit(0)
            where = f"{ctx.command_path}: " if ctx is not None else ""
            message = " ".join(exc.format_message().split())
            typer.echo(f"error: {where}{message} (see --help)", err=True)
            sys.exit(exc.exit_code)
        except typer.Abort:
            typer.echo("Aborted.", err=True)
            sys.exit(1)
        sys.exit(rv if isinstance(rv, int) else 0)


app = typer.Typer(
    cls=OneLineErrors,
    name="diegocal",
    help="Calibrate and identify compliant, sensor-rich robots (STAC, SGP, pneumatic models).",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)

simulate_app = typer.Typer(
    help="Generate logs with ground truth in /truth: kinematics, dynamics, pneumatics.",
    no_args_is_help=True,
    pretty_exceptions_enable=False,
)
app.add_typer(simulate_app, name="simulate")
