"""Marker trajectories exported as CSV by the mocap vendors' software: Vicon Nexus and OptiTrack Motive.

**Vicon Nexus** (Nexus "Export CSV"; Vicon's Nexus user guide, "CSV file format"): sections, each
ended by a blank line::

    Trajectories                                  section name (also Devices, Model Outputs, ...)
    100                                           its rate, Hz
    ,,PR2:ua1,,,PR2:ua2,,,                        names over each group's first column
    Frame,Sub Frame,X,Y,Z,X,Y,Z                   components
    ,,mm,mm,mm,mm,mm,mm                           units
    1,0,12.1,45.6,78.9,,,                         one row per frame (per sub frame for devices);
                                                  an occluded marker's cells are empty
Tables: ``trajectories`` (markers, each (T, 3), time (frame − 1) / rate) and ``devices`` (analog
channels named ``<device>.<component>``, at the device rate).

**OptiTrack Motive** (Motive's "Data Export: CSV", format versions 1.2x)::

    Format Version,1.23,Take Name,t1,Capture Frame Rate,120,Export Frame Rate,120,...,Length Units,Millimeters
    (blank)
    ,Type,Rigid Body,...,Rigid Body Marker,...,Marker,Marker,Marker
    ,Name,arm,...,arm:Marker1,...,PR2:ua1,PR2:ua1,PR2:ua1
    ,ID,1,...                                    (and a Parent row in newer versions)
    ,,Rotation,...,Position,...,Position,Position,Position
    Frame,Time (Seconds),X,Y,Z,W,...,X,Y,Z
Tables: ``markers`` (labelled markers; "Unlabeled" ones left out), ``rigid_bodies`` (each body's
position) and ``rigid_body_markers`` (where the solved bodies put their markers), in ``Length
Units`` (metres when the file does not say).
"""

from __future__ import annotations

import csv
import io
from dataclasses import replace
from pathlib import Path

import numpy as np

from diegocal.errors import LogFormatError
from diegocal.io.importers.mapping import SourceSpec
from diegocal.io.importers.tables import GENERIC, POINTS, Source, Table, check_increasing, finish_time, numeric_block

#: Motive's Length Units -> the unit names of the import.
_MOTIVE_UNITS = {"meters": "m", "millimeters": "mm", "centimeters": "cm"}
#: Motive's column types -> table names.
_MOTIVE_TABLES = {"Marker": "markers", "Rigid Body": "rigid_bodies", "Rigid Body Marker": "rigid_body_markers"}


def sniff(path: Path) -> str | None:
    """'vicon' or 'motive' when the first line of a CSV is one of theirs, else None."""
    with open(path, errors="replace") as fh:
        first = fh.readline().strip()
    cell = first.split(",")[0].strip().strip('"')
    if cell == "Format Version":
        return "motive"
    if cell in ("Trajectories", "Devices", "Joints", "Model Outputs", "Segments") and first.strip(",") == cell:
        return "vicon"
    return None


def open_mocap_csv(path: Path, spec: SourceSpec, kind: str) -> Source:
    tables = read_vicon(path, spec) if kind == "vicon" else read_motive(path, spec)
    default = "trajectories" if kind == "vicon" else "markers"
    if default not in tables:
        raise LogFormatError(f"{path}: no {default} in this {kind} export (it has {', '.join(tables) or 'nothing'})")
    return Source(spec=spec, path=path, kind=kind, table_names=tuple(tables), loader=tables.__getitem__,
                  default_table=default)


# ----------------------------------------------------------------------------- Vicon Nexus
def read_vicon(path: Path, spec: SourceSpec) -> dict[str, Table]:
    lines = path.read_text(errors="replace").splitlines()
    sections, i = {}, 0
    while i < len(lines):
        title = lines[i].strip().strip(",")
        if not title:
            i += 1
            continue
        end = next((k for k in range(i + 1, len(lines)) if not lines[k].strip().strip(",")), len(lines))
        sections[title] = lines[i:end]
        i = end
    if "Trajectories" not in sections:
        raise LogFormatError(f"{path}: no Trajectories section (sections: {', '.join(sections) or 'none'})")
    rate = _vicon_rate(sections["Trajectories"], path)
    tables = {"trajectories": _vicon_section(sections["Trajectories"], path, spec, rate, markers=True)}
    skipped = [t for t in sections if t not in ("Trajectories", "Devices")]
    if skipped:
        tables["trajectories"] = replace(tables["trajectories"], notes=(
            f"{path.name}: sections not read: {', '.join(skipped)}",))
    if "Devices" in sections:
        tables["devices"] = _vicon_section(sections["Devices"], path, spec, rate, markers=False)
    return tables


def _vicon_rate(section: list[str], path: Path) -> float:
    try:
        rate = float(section[1].split(",")[0])
    except (IndexError, ValueError):
        raise LogFormatError(f"{path}: {section[0].strip(',')}: the line after the section name should be its "
                             "rate (Hz)") from None
    if not rate > 0:
        raise LogFormatError(f"{path}: {section[0].strip(',')}: rate {rate:g} Hz")
    return rate


def _vicon_section(section: list[str], path: Path, spec: SourceSpec, frame_rate: float, markers: bool) -> Table:
    title = section[0].strip(",")
    rate = _vicon_rate(section, path)
    if len(section) < 6 or not section[3].startswith("Frame"):
        raise LogFormatError(f"{path}: {title}: expected the names, 'Frame,Sub Frame,...' and units rows, then data")
    names, comps, units = (_row(line) for line in section[2:5])
    data = numeric_block(section[5:], len(comps), path, sep=",")
    groups = _groups(names, comps)
    if markers:
        columns, col_units = {}, {}
        for name, cols in groups.items():
            axes = {comps[k]: k for k in cols}
            if all(a in axes for a in "XYZ"):
                columns[name] = data[:, [axes["X"], axes["Y"], axes["Z"]]]
                col_units[name] = units[axes["X"]] if axes["X"] < len(units) else ""
        time = (data[:, 0] - 1.0) / rate
        kind = POINTS
    else:
        columns = {f"{name}.{comps[k]}": data[:, k] for name, cols in groups.items() for k in cols}
        col_units = {f"{name}.{comps[k]}": units[k] for name, cols in groups.items() for k in cols if k < len(units)}
        time = (data[0, 0] - 1.0) / frame_rate + np.arange(data.shape[0]) / rate
        kind = GENERIC
    check_increasing(time, f"{path}: {title}")
    return Table(name=title.lower(), time=finish_time(time, spec, float(time[0])), columns=columns, kind=kind,
                 units={k: u for k, u in col_units.items() if u}, rate_hz=rate)


def _groups(names: list[str], comps: list[str]) -> dict[str, list[int]]:
    """Column indices per name; a name stands over its group's first column (data from column 2)."""
    groups, current = {}, None
    for k in range(2, len(comps)):
        if k < len(names) and names[k]:
            current = names[k]
            if current in groups:
                raise LogFormatError(f"name {current!r} appears twice in the names row")
            groups[current] = []
        if current is not None and comps[k]:
            groups[current].append(k)
    return groups


def _row(line: str) -> list[str]:
    return [c.strip() for c in next(csv.reader(io.StringIO(line)))] if line.strip() else []


# ----------------------------------------------------------------------------- OptiTrack Motive
def read_motive(path: Path, spec: SourceSpec) -> dict[str, Table]:
    lines = path.read_text(errors="replace").splitlines()
    meta_cells = _row(lines[0])
    meta = dict(zip(meta_cells[::2], meta_cells[1::2], strict=False))
    frame_row = next((i for i, ln in enumerate(lines) if ln.startswith("Frame,")), None)
    if frame_row is None:
        raise LogFormatError(f"{path}: Motive CSV without its 'Frame,Time (Seconds),X,Y,Z,...' row")
    header = [_row(ln) for ln in lines[1:frame_row] if ln.strip().strip(",")]
    labelled = {r[1]: r for r in header if len(r) > 1 and r[1] in ("Type", "Name", "ID", "Parent")}
    if "Type" not in labelled:  # format 1.21: Type, Name, ID rows without their labels
        labelled = dict(zip(("Type", "Name", "ID"), header[:-1], strict=False))
    if "Type" not in labelled or "Name" not in labelled or len(header) < 2:
        raise LogFormatError(f"{path}: Motive CSV without its Type and Name rows above the Frame row")
    types, names, quantity = labelled["Type"], labelled["Name"], header[-1]
    comps = _row(lines[frame_row])
    data = numeric_block(lines[frame_row + 1:], len(comps), path, sep=",")
    unit = _MOTIVE_UNITS.get(meta.get("Length Units", "Meters").strip().lower())
    if unit is None:
        raise LogFormatError(f"{path}: Motive Length Units {meta['Length Units']!r} (expected Meters, Centimeters "
                             "or Millimeters)")
    time = data[:, 1]
    check_increasing(time, f"{path}: Time column")
    time = finish_time(time, spec, float(time[0]))
    rate = _rate(meta, path)
    points: dict[str, dict] = {}
    for k in range(2, len(comps)):
        kind = _MOTIVE_TABLES.get(types[k] if k < len(types) else "")
        name = names[k] if k < len(names) else ""
        if kind is None or not name or name.startswith("Unlabeled") or quantity[k:k + 1] != ["Position"]:
            continue
        points.setdefault(kind, {}).setdefault(name, {})[comps[k]] = data[:, k]
    tables = {}
    for kind, cols in points.items():
        columns = {n: np.column_stack([axes[a] for a in "XYZ"]) for n, axes in cols.items()
                   if all(a in axes for a in "XYZ")}
        tables[kind] = Table(name=kind, time=time, columns=columns, kind=POINTS, units=dict.fromkeys(columns, unit),
                             rate_hz=rate)
    return tables


def _rate(meta: dict, path: Path) -> float | None:
    for key in ("Export Frame Rate", "Capture Frame Rate"):
        if meta.get(key):
            try:
                return float(meta[key])
            except ValueError:
                raise LogFormatError(f"{path}: Motive {key} {meta[key]!r} is not a number") from None
    return None
