"""The Typer application, its sub-apps and the table of commands; command modules attach themselves.

A command's module is imported only when that command runs or shows its help (pip's
``commands/__init__.py`` names each command's module as a string the same way): :data:`COMMANDS`
names the module and the one line ``diegocal --help`` shows, so the command list needs no module.
Command modules import only the standard library, typer, rich and ``diegocal.cli`` at module level
(heavy libraries inside the command that runs), so every help answers at once;
tests/cli/test_light_help.py counts the modules a help loads and checks this table against the
commands' own docstrings.
"""

import importlib
import sys

import typer
from typer.core import TyperArgument, TyperCommand, TyperGroup, TyperOption

#: Command path -> (the module that defines it, the line the command list shows: the first paragraph
#: of its help). In the order `diegocal --help` lists them: make or bring a log, fit, use, report, batch.
COMMANDS: dict[tuple[str, ...], tuple[str, str]] = {
    ("simulate", "kinematics"): (
        "diegocal.cli.simulate_cmd",
        "Simulate a kinematic calibration session (thesis §2.5.1) with truth in /truth.",
    ),
    ("simulate", "dynamics"): (
        "diegocal.cli.simulate_dynamics_cmd",
        "Simulate q, qd, qdd, tau of any robot (thesis eq. 3.29 + effects) with truth in /truth.",
    ),
    ("simulate", "pneumatics"): (
        "diegocal.cli.pneumatic_cmd",
        "Simulate valve-chamber systems with the thin-plate physics (thesis §4.2), truth in /truth.",
    ),
    ("import",): (
        "diegocal.cli.import_cmd",
        "Turn motion capture (C3D, TRC, Vicon Nexus and OptiTrack Motive CSV), ROS bags and lab CSVs into one "
        "diegocal log on one clock.",
    ),
    ("inspect",): (
        "diegocal.cli.inspect_cmd",
        "Describe a log: streams, channel names, duration, rate, NaN or occlusion per channel.",
    ),
    ("split",): (
        "diegocal.cli.split_cmd",
        "Cut a log in two contiguous parts in time: TRAIN to fit on, HELDOUT to predict.",
    ),
    ("stac",): (
        "diegocal.cli.stac_cmd",
        "Calibrate pots, markers and the mocap frame; track joint angles (thesis ch. 2).",
    ),
    ("poses",): (
        "diegocal.cli.poses_cmd",
        (
            "Propose the next N static poses for stac --geometry among candidate poses: I-optimal (the "
            "markers' predictions most precise) by default, D-optimal with --criterion D."
        ),
    ),
    ("sgp-fit",): (
        "diegocal.cli.sgp_cmd",
        "Fit a torque model: parametric (rigid body + friction) part, GP part and hyperparameters.",
    ),
    ("pneumatic-fit",): (
        "diegocal.cli.pneumatic_cmd",
        "Fit the 9-parameter valve-chamber model (thesis §4.5.3) by next-step least squares.",
    ),
    ("pneumatic-merge",): (
        "diegocal.cli.pneumatic_cmd",
        "Merge per-chamber pneumatic.yaml files (from `make -j`) into one.",
    ),
    ("predict",): (
        "diegocal.cli.predict_cmd",
        "Predict a held-out log with a fitted model and report the error (the model file is only read).",
    ),
    ("diagnose",): (
        "diegocal.cli.diagnose_cmd",
        "Show what the model gets wrong, name the cause, extend the model and measure the gain on held-out "
        "blocks of the log.",
    ),
    ("report",): (
        "diegocal.cli.report_cmd",
        "Write one PDF document: contents and summary, then one section per result; print the summary.",
    ),
    ("batch",): (
        "diegocal.cli.batch_cmd",
        "Run a command over every log of a folder: one output per log, skipping logs whose outputs are newer "
        "(as make does), and a merged table of the results (CSV and a report page).",
    ),
}

#: ``ctx.meta`` key set while a group prints its help: its command list needs no module.
_LISTING = "diegocal.listing"


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


class _HelpFlag(TyperOption):
    """A group's ``--help``: a flag, read without typer's value coercion (which imports pydantic,
    a tenth of a second, in every ``diegocal COMMAND --help`` that passes through the group)."""

    def process_value(self, ctx, value):
        value = bool(value)
        return self.callback(ctx, self, value) if self.callback is not None else value


class Group(TyperGroup):
    """A command group whose commands are imported when used (:data:`COMMANDS`) and whose help
    reads as sentences (:func:`_tidy`)."""

    def get_help_option(self, ctx):
        option = super().get_help_option(ctx)
        if type(option) is TyperOption:
            option.__class__ = _HelpFlag
        return option

    @property
    def path(self) -> tuple[str, ...]:
        """This group's command path below ``diegocal``."""
        return (self.name,)

    def list_commands(self, ctx) -> list[str]:
        listed = [p[-1] for p in COMMANDS if p[:-1] == self.path]
        groups = [n for n, c in self.commands.items() if isinstance(c, TyperGroup)]
        return list(dict.fromkeys(groups + listed + list(self.commands)))

    def get_command(self, ctx, cmd_name):
        command = self.commands.get(cmd_name)
        entry = COMMANDS.get((*self.path, cmd_name))
        if command is None and entry is not None:
            if ctx.meta.get(_LISTING):  # the command list: its line, without importing the module
                return TyperCommand(cmd_name, short_help=entry[1])
            command = self._load(cmd_name, entry[0])
        if command is not None:
            _tidy(command, ctx)
        return command

    def _load(self, name: str, module: str):
        """Import the command's module (it registers the command on its Typer app) and build it."""
        importlib.import_module(module)
        built = typer.main.get_command(app)
        for part in (*self.path, name):
            built = built.commands.get(part) if isinstance(built, TyperGroup) else None
        if built is not None:
            self.add_command(built, name)
        return built

    def format_help(self, ctx, formatter):
        _tidy(self, ctx)
        ctx.meta[_LISTING] = True
        try:
            return super().format_help(ctx, formatter)
        finally:
            ctx.meta.pop(_LISTING, None)


class OneLineErrors(Group):
    """The ``diegocal`` group. Usage errors (a bad option value, a missing argument) are one line on
    stderr, exit 2, like every other bad input (STYLE.md), instead of the multi-line usage box; a
    library error raised while the options are read (an output folder that does not exist) is one
    line, exit 1."""

    @property
    def path(self) -> tuple[str, ...]:
        return ()

    def main(self, args=None, prog_name=None, standalone_mode=True, **extra):
        if not standalone_mode:
            return super().main(args, prog_name, standalone_mode=False, **extra)
        from diegocal.errors import DiegocalError

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
        except DiegocalError as exc:  # raised by an option's callback, before the command runs
            from diegocal.cli.common import fail

            fail(str(exc))
            sys.exit(1)
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
    rich_markup_mode=None,  # plain help: rich's boxed panels cost a help a third of its start-up
)

simulate_app = typer.Typer(
    cls=Group,
    help="Generate logs with ground truth in /truth: kinematics, dynamics, pneumatics.",
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,
)
app.add_typer(simulate_app, name="simulate")


def click_command(path: tuple[str, ...]):
    """The click command at ``path`` (``("stac",)``, ``("simulate", "kinematics")``): what parses its
    arguments (``.make_context(name, args)``), as the command line does. KeyError for no such command."""
    command = typer.main.get_command(app)
    ctx = typer.Context(command, info_name="diegocal")
    for name in path:
        command = command.get_command(ctx, name) if isinstance(command, TyperGroup) else None
        if command is None:
            raise KeyError(f"no command {' '.join(path)!r}")
        ctx = typer.Context(command, parent=ctx, info_name=name)
    return command
