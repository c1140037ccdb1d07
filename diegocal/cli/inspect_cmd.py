"""`diegocal inspect LOG`: streams, names, duration, rate, NaN/occlusion fraction per channel."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from diegocal.cli.app import app
from diegocal.cli.common import cli_errors, console, warn


@app.command("inspect")
@cli_errors
def inspect(log: Annotated[Path, typer.Argument(help="A diegocal log (.h5 or .csv).")]) -> None:
    """Describe a log: streams, channel names, duration, rate, NaN or occlusion per channel."""
    # the library is imported when the command runs, so that `--help` answers at once
    from rich.markup import escape
    from rich.table import Table

    from diegocal.io import load_log
    from diegocal.io.describe import describe_log
    from diegocal.io.log import NAN_ALLOWED

    s = describe_log(load_log(log, nan_ok=True))
    console.print(
        f"[bold]{escape(str(log))}[/]  robot={escape(s.robot or '-')}  samples={s.n_samples}  "
        f"duration={s.duration:.3f} s  rate={s.rate_hz:.4g} Hz"
        + (f" (nominal {s.nominal_rate_hz:g})" if s.nominal_rate_hz else "")
        + (r"  \[truth: yes]" if s.has_truth else ""),
        highlight=False,
    )
    for st in s.streams:
        table = Table(title=f"{st.name}  {st.shape}", title_justify="left")
        for col in ("channel", "min", "max", "NaN %" if st.name != "markers" else "occluded %"):
            table.add_column(col)
        for k, name in enumerate(st.names):
            table.add_row(escape(name), f"{st.low[k]:.4g}", f"{st.high[k]:.4g}", f"{100 * st.nan_fraction[k]:.1f}")
        console.print(table)
    bad = [st.name for st in s.streams if st.name not in NAN_ALLOWED and st.nan_fraction.any()]
    if bad:
        warn(f"NaN in stream(s) {', '.join(bad)}: only markers may be NaN, so fitting commands will refuse this log")
