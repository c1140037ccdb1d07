"""The Typer application and its sub-apps; command modules attach themselves to these."""

import typer

app = typer.Typer(
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
