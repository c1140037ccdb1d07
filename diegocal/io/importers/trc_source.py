"""TRC marker files ("Track Row Column", Motion Analysis Cortex; OpenSim's marker format).

Layout (tab-separated; OpenSim's ``Marker (.trc) Files`` page, Cortex's export)::

    PathFileType  4  (X/Y/Z)  walk.trc
    DataRate  CameraRate  NumFrames  NumMarkers  Units  OrigDataRate  OrigDataStartFrame  OrigNumFrames
    100.00    100.00      500        2           mm     100.00        1                   500
    Frame#  Time  RASI            LASI
                  X1   Y1   Z1    X2   Y2   Z2
    (an optional blank line)
    1       0.000 12.1 45.6 78.9  ...

Table ``points``: one (T, 3) column per marker name, in ``Units`` (mm or m), NaN where a cell is
empty (an occluded marker); time from the ``Time`` column, s. A file with fewer frames than
``NumFrames`` is cut short: an error unless the source says ``allow_truncated: true``.
"""

from __future__ import annotations

import logging
import re
from pathlib import Path

from diegocal.errors import LogFormatError
from diegocal.io.importers.mapping import SourceSpec
from diegocal.io.importers.tables import POINTS, Source, Table, check_increasing, finish_time, numeric_block

log = logging.getLogger(__name__)


def open_trc(path: Path, spec: SourceSpec) -> Source:
    """A TRC source with one table, ``points``."""
    table = read_trc(path, spec)
    return Source(spec=spec, path=path, kind="trc", table_names=("points",), loader=lambda _name: table,
                  default_table="points")


def read_trc(path: Path, spec: SourceSpec) -> Table:
    lines = path.read_text(errors="replace").splitlines()
    if len(lines) < 6 or not lines[0].startswith("PathFileType"):
        raise LogFormatError(f"{path}: not a TRC file (its first line should start with PathFileType)")
    keys, values = _cells(lines[1]), _cells(lines[2])
    if len(values) < len(keys) or "DataRate" not in keys:
        raise LogFormatError(f"{path}: TRC line 2 should name DataRate, NumFrames, NumMarkers, Units over line 3")
    info = dict(zip(keys, values, strict=False))
    names = [c for c in _cells(lines[3])[2:] if c]
    if not names or _cells(lines[3])[:2] != ["Frame#", "Time"]:
        raise LogFormatError(f"{path}: TRC line 4 should be Frame#, Time and the marker names")
    try:
        rate, frames = float(info["DataRate"]), int(float(info.get("NumFrames", "0")))
    except ValueError:
        raise LogFormatError(f"{path}: TRC DataRate / NumFrames are not numbers") from None
    rows = [ln for ln in lines[5:] if ln.strip()]
    data = numeric_block(rows, 2 + 3 * len(names), path)
    if 0 < data.shape[0] < frames:
        what = f"{path.name}: truncated: NumFrames is {frames}, the file holds {data.shape[0]} frames"
        if not spec.allow_truncated:
            raise LogFormatError(f"{what}; set `allow_truncated: true` for this source in the map to import them")
        log.warning("%s; importing them (allow_truncated)", what)
    time = data[:, 1]
    check_increasing(time, f"{path}: Time column")
    unit = info.get("Units") or None
    columns = {n: data[:, 2 + 3 * k: 5 + 3 * k] for k, n in enumerate(names)}
    return Table(name="points", time=finish_time(time, spec, float(time[0])), columns=columns, kind=POINTS,
                 units={n: unit for n in names} if unit else {}, rate_hz=rate if rate > 0 else None)


def _cells(line: str) -> list[str]:
    """A TRC line's cells: tab-separated (empty cells kept), else separated by runs of blanks."""
    return [c.strip() for c in line.split("\t")] if "\t" in line else re.split(r"\s+", line.strip())
