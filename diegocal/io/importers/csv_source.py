"""CSV exports: ``rostopic echo -p``, diegocal's own CSV layout, and any table with a time column.

``rostopic echo -p /joint_states`` writes ``%time`` (receive time, ns), ``field.header.stamp``
(ns), ``field.name0..``, ``field.position0..``, ``field.velocity0..``, ``field.effort0..``;
the table gets columns ``position.<joint>`` etc. like a bag's JointState topic. Other topics'
columns lose their ``field.`` prefix (``field.wrench.force.x`` -> ``wrench.force.x``).
Any other CSV needs a time column (``time`` unless the map names one, e.g. ``time: t``) or a
``rate_hz`` in the map; text columns are left out (and named if asked for).
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from diegocal.errors import LogFormatError
from diegocal.io.importers.mapping import STREAMS, MapError, SourceSpec
from diegocal.io.importers.tables import (
    DIEGOCAL,
    GENERIC,
    JOINT_STATE,
    Source,
    Table,
    check_increasing,
    finish_time,
    preview,
    sort_unique,
)
from diegocal.io.importers.units import close_match, header_unit, time_factor

_ROSTOPIC_TIME = "%time"
_JS_FIELD = re.compile(r"^field\.(name|position|velocity|effort)(\d+)$")


def open_csv(path: Path, spec: SourceSpec) -> Source:
    """A CSV source with one table (named '')."""
    table = read_csv_table(path, spec)
    return Source(spec=spec, path=path, kind="csv", table_names=("",), loader=lambda _name: table)


def read_csv_table(path: Path, spec: SourceSpec) -> Table:
    frame = _read_frame(path)
    columns = [str(c) for c in frame.columns]
    if columns and columns[0] == _ROSTOPIC_TIME:
        return _rostopic(path, frame, spec)
    time_col = spec.time
    if spec.rate_hz is not None:
        time = np.arange(len(frame)) / spec.rate_hz
        time_col = None
    else:
        if time_col is None:
            if "time" not in columns:
                raise MapError(f"{path}: no 'time' column (columns: {preview(columns)}); name the time column "
                               "with `time:` or give `rate_hz:` for this source in the map"
                               + close_match("time", columns))
            time_col = "time"
        if time_col not in columns:
            raise MapError(f"{path}: no time column {time_col!r} (columns: {preview(columns)})"
                           + close_match(time_col, columns))
        time = _numeric(frame[time_col], path, time_col)
        if time is None:
            raise LogFormatError(f"{path}: time column {time_col!r} holds non-numeric values")
        time = time * time_factor(spec.time_unit or "s")
    check_increasing(time, f"{path}: column {time_col or 'time'}", repeats=True)
    data, text = {}, []
    for col in columns:
        if col == time_col:
            continue
        values = _numeric(frame[col], path, col)
        if values is None:
            text.append(col)
        else:
            data[col] = values
    kind = DIEGOCAL if data and all(_diegocal_column(c) for c in data) else GENERIC
    units, header = {}, {c: u for c in data if (u := header_unit(c))}  # `x [mV]`: a unit the map need not repeat
    if kind == DIEGOCAL:  # already in the log's units; only markers need saying (m)
        data = _group_markers(data)
        units, header = {c: "m" for c in data if c.startswith("markers.")}, {}
    notes = (f"{path.name}: text columns left out: {preview(text)}",) if text else ()
    # a stamp written twice (a logger's resend): the first row kept, as a bag's (never out of order here)
    time, values, dropped = sort_unique(time, list(data.values()), path.name)
    data, notes = dict(zip(data, values, strict=True)), notes + dropped
    time = finish_time(time, spec, float(time[0]))
    rate = spec.rate_hz
    return Table(name="", time=time, columns=data, kind=kind, units=units, rate_hz=rate, notes=notes,
                 header_units=header)


def _rostopic(path: Path, frame, spec: SourceSpec) -> Table:
    """A ``rostopic echo -p`` export: header stamps (ns) or receive time, ``field.`` columns."""
    columns = [str(c) for c in frame.columns]
    stamp_col = "field.header.stamp"
    use = _ROSTOPIC_TIME
    if spec.time is not None:
        use = spec.time
        if use not in columns:
            raise MapError(f"{path}: no time column {use!r}" + close_match(use, columns))
    elif spec.stamp == "header" and stamp_col in columns:
        stamps = _numeric(frame[stamp_col], path, stamp_col)
        if stamps is not None and (stamps > 0).all():
            use = stamp_col
    raw, ns = _stamps(frame[use], path, use, spec.time_unit or "ns")
    fields = {m.group(1): {} for c in columns if (m := _JS_FIELD.match(c))}
    for c in columns:
        if m := _JS_FIELD.match(c):
            fields[m.group(1)][int(m.group(2))] = c
    data = {}
    kind = GENERIC
    if "name" in fields and "position" in fields:
        kind = JOINT_STATE
        names = []
        for k in sorted(fields["name"]):
            col = frame[fields["name"][k]].astype(str)
            if (col != col.iloc[0]).any():
                raise LogFormatError(f"{path}: joint names change between rows in column {fields['name'][k]!r}")
            names.append(str(col.iloc[0]).strip())
        for quantity in ("position", "velocity", "effort"):
            for k, col in sorted(fields.get(quantity, {}).items()):
                if k >= len(names):
                    raise LogFormatError(f"{path}: column {col!r} has no joint name (field.name{k})")
                values = _numeric(frame[col], path, col)
                if values is None:
                    raise LogFormatError(f"{path}: column {col!r} holds non-numeric values")
                data[f"{quantity}.{names[k]}"] = values
    else:
        for c in columns:
            if c in (_ROSTOPIC_TIME, stamp_col) or not c.startswith("field."):
                continue
            values = _numeric(frame[c], path, c)
            if values is not None:
                data[c[len("field."):]] = values
    rel = None if ns is None else (ns - ns.min()) * 1e-9
    extra = [] if rel is None else [rel]
    raw, values, notes = sort_unique(raw, list(data.values()) + extra, f"{path.name} ({use})")
    if rel is not None:
        rel = values.pop()
    check_increasing(raw, f"{path}: column {use}")
    time = finish_time(raw, spec, float(raw[0]), rel)
    return Table(name="", time=time, columns=dict(zip(data, values, strict=True)), kind=kind,
                 notes=(f"{path.name}: rostopic CSV, time from {use}", *notes))


def _stamps(series, path: Path, col: str, unit: str):
    """Time stamps in s, and the integer nanoseconds when the column holds them (exact zero_time)."""
    import pandas as pd

    if pd.api.types.is_integer_dtype(series) and unit == "ns":
        ns = series.to_numpy(dtype=np.int64)
        return ns * 1e-9, ns
    values = _numeric(series, path, col)
    if values is None:
        raise LogFormatError(f"{path}: time column {col!r} holds non-numeric values")
    return values * time_factor(unit), None


def _read_frame(path: Path):
    import pandas as pd

    skip = 0
    with open(path, errors="replace") as fh:
        header = fh.readline()
        if header.startswith("#"):
            skip = 1  # diegocal's '# diegocal-log ...' header line
            header = fh.readline()
    sep, decimal = _delimiter(header)
    try:
        frame = pd.read_csv(path, skiprows=skip, skipinitialspace=False, sep=sep, decimal=decimal)
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        raise LogFormatError(f"{path}: cannot parse CSV ({str(exc).splitlines()[0]})") from None
    if len(frame) == 0:
        raise LogFormatError(f"{path}: CSV has a header but no rows")
    names = [str(c) for c in frame.columns]
    dup = [c for c in names if re.search(r"\.\d+$", c) and c.rsplit(".", 1)[0] in names]
    if dup:
        raise LogFormatError(f"{path}: duplicate column {dup[0].rsplit('.', 1)[0]!r}")
    return frame


def _delimiter(header: str) -> tuple[str, str]:
    """(column separator, decimal mark) of a CSV from its header: a comma, or a semicolon or tab
    where the header has those and no comma (a semicolon-separated export is European: its numbers
    may use a decimal comma, which pandas reads beside a decimal point)."""
    if "," in header or not (";" in header or "\t" in header):
        return ",", "."
    sep = ";" if header.count(";") >= header.count("\t") else "\t"
    return sep, "," if sep == ";" else "."  # pandas still reads "1.5" with decimal=","


def _numeric(series, path: Path, col: str) -> np.ndarray | None:
    """float64 values, NaN for empty cells; None when a cell holds text."""
    import pandas as pd

    if pd.api.types.is_numeric_dtype(series):
        return series.to_numpy(dtype=np.float64)
    values = pd.to_numeric(series, errors="coerce")
    if (values.isna() & series.notna() & (series.astype(str).str.strip() != "")).any():
        return None
    return values.to_numpy(dtype=np.float64)


def _diegocal_column(col: str) -> bool:
    return "." in col and col.split(".", 1)[0] in STREAMS


def _group_markers(data: dict) -> dict:
    """``markers.<name>.x|y|z`` columns -> one (T, 3) column ``markers.<name>``."""
    out = {}
    for col, values in data.items():
        stream, rest = col.split(".", 1)
        if stream != "markers":
            out[col] = values
            continue
        if rest[-2:] not in (".x", ".y", ".z"):
            raise LogFormatError(f"column {col!r} should end in .x, .y or .z")
        name = f"markers.{rest[:-2]}"
        if name in out:
            continue
        try:
            out[name] = np.stack([data[f"{name}.{a}"] for a in "xyz"], axis=1)
        except KeyError:
            raise LogFormatError(f"marker {rest[:-2]!r} needs .x, .y and .z columns") from None
    return out

