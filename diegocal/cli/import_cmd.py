"""`diegocal import SRC... [--map MAP.yaml] -o LOG`: lab files (C3D, TRC, ROS bags, CSV exports) -> one log."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from diegocal.cli.app import app
from diegocal.cli.common import cli_errors, distinct_output, log_output, positive, summary

HELP = (
    "Turn motion capture (C3D, TRC, Vicon Nexus and OptiTrack Motive CSV), ROS bags and lab CSVs into one "
    "diegocal log on one clock.\n\n"
    "The map (YAML) has the keys robot; sources (file pattern, time column or rate_hz, time_offset in s or auto, "
    "zero_time, stamp, max_gap_s, allow_truncated); streams (source, table or topic, columns: file column -> "
    "channel, unit, side: motor, scale, offset, torque_constant, time_offset, subject); transmission (ratio); "
    "clock (rate_hz or source); interpolation (linear, nearest, previous); filter (cutoff_hz, order); derive "
    "(qd, qdd); window (auto, or start and stop in s). docs/import.md describes the formats and every key; "
    "sample_data/real/*.map.yaml are worked examples."
)


@app.command("import", help=HELP)
@cli_errors
def import_cmd(
    sources: Annotated[list[Path], typer.Argument(
        metavar="SRC",
        help="C3D (.c3d), TRC (.trc), ROS bags (.bag, .db3, .mcap or a ROS 2 bag folder), CSV exports "
        "(Vicon Nexus, OptiTrack Motive, rostopic echo -p, lab tables, diegocal CSV).")],
    output: Annotated[
        Path, typer.Option("--output", "-o", callback=log_output, help="Log to write (.h5 or .csv).")
    ],
    map_file: Annotated[Path | None, typer.Option(
        "--map", help="Import map (YAML): sources, columns -> channels, units, transmission, clock, "
        "filter, derive, window. Without it each file gives its natural streams.")] = None,
    rate: Annotated[float | None, typer.Option(
        callback=positive, help="Clock of the log in Hz, replacing the map's clock; by default the map's clock, "
        "else the C3D's time stamps, else those the files share.")] = None,
    robot: Annotated[str | None, typer.Option(
        help="Robot the log names (a bundled name, a robot directory, a URDF or xacro file); by default the map's "
        "robot. Joint units, mimic joints and marker names are checked against it.")] = None,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No summary table.")] = False,
) -> None:
    """Turn C3D motion capture, ROS bags and lab CSVs into one diegocal log on one clock."""
    from diegocal.io import save_log
    from diegocal.io.importers import ImportMap, import_log, load_map

    distinct_output((output,), (*sources, map_file))
    mapping = load_map(map_file) if map_file is not None else ImportMap()
    result = import_log(sources, mapping, rate_hz=rate, robot=robot)
    save_log(result.log, output)
    log = result.log
    rows = [(f"source {name}", f"{Path(path).name} ({kind})") for name, path, kind in result.sources]
    rows += [(f"stream {stream}", f"{n} channels {origin}; {conversion}")
             for stream, origin, n, conversion in result.streams]
    rows += [("clock", result.clock), ("samples", log.n_samples), ("time", time_span(log.time))]
    rows += [(f"clock offset {e.other}",
              f"{e.offset_s:+.4g} s ± {e.se_s:.2g} s against {e.reference} ({e.signals}, r = {e.r:.2f})")
             for e in result.offsets]
    if log.has("markers"):
        import numpy as np

        rows.append(("occluded marker samples", f"{float(np.isnan(log.streams['markers'].data[..., 0]).mean()):.1%}"))
    rows += [("note", n) for n in result.notes]
    rows += [("robot", log.robot or "none: give --robot, or robot: in the map"), ("written", str(output))]
    summary("import", rows, quiet=quiet)


#: Time stamps past this (s) are taken as Unix time (ROS, PTP clocks): about 1 year after 1970.
EPOCH_AFTER_S = 3.15e7


def time_span(time) -> str:
    """The log's time span in words: its duration, and its start as a UTC date for Unix time stamps
    (``1.7e+09 .. 1.7e+09`` says nothing)."""
    t0, t1 = float(time[0]), float(time[-1])
    if abs(t0) < EPOCH_AFTER_S:
        return f"{t0:.6g} .. {t1:.6g} s ({t1 - t0:.6g} s)"
    from datetime import UTC, datetime

    start = datetime.fromtimestamp(t0, UTC).strftime("%Y-%m-%d %H:%M:%S.%f")[:-3]
    return f"{t1 - t0:.6g} s from {start} UTC (Unix time {t0:.3f} s)"
