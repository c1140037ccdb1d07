"""The Typer application and its sub-apps; command modules attach themselves to these.

Command modules import only the standard library, typer, rich and ``diegocal.cli`` at module
level (heavy libraries inside the command that runs), so `diegocal --help` and every
`COMMAND --help` answer at once; tests/cli/test_light_help.py counts the modules a help loads.
"""

import sys

import typer
from typer.core import TyperArgument, TyperGroup, TyperOption


def _tidy(command, ctx) -> None:
    """The help as sentences (once per command): a flag shows no ``<bool>`` value (it takes none),
    an argument reads as its upper-case name (``LOG``), and the command list shows a command's
    first paragraph on one line."""
    if getattr(command, "_diegocal_tidy", False):
        return
    for param in command.get_params(ctx):
        if isinstance(param, TyperOption) and param.is_flag and param.metavar is None:
            param.metavar = ""
        elif isinstance(param, TyperArgument) and param.metavar is None:
            param.metavar = param.name.upper()
    if command.short_help is None and command.help:
        command.short_help = " ".join(command.help.strip().split("\n\n", 1)[0].split())
    command._diegocal_tidy = True


class Group(TyperGroup):
    """A command group whose commands' help reads as sentences (:func:`_tidy`)."""

    def get_command(self, ctx, cmd_name):
        command = super().get_command(ctx, cmd_name)
        if command is not None:
            _tidy(command, ctx)
        return command

    def format_help(self, ctx, formatter):
        _tidy(self, ctx)
        return super().format_help(ctx, formatter)


class OneLineErrors(Group):
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
            # typer validates values with pydantic, whose messages start "Value error, "
            message = " ".join(exc.format_message().replace("Value error, ", "").split())
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
    cls=Group,
    help="Generate logs with ground truth in /truth: kinematics, dynamics, pneumatics.",
    no_args_is_help=True,
    pretty_exceptions_enable=False,
)
app.add_typer(simulate_app, name="simulate")
