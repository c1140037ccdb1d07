"""Files + map -> one diegocal log: channels, units, transmission, filtering, one clock, window.

Order of the steps, per stream:

1. take the mapped columns of one table (or its natural channels: a C3D's markers, a JointState's
   q/qd/tau, a diegocal CSV's ``<stream>.<name>``);
2. convert to the log's unit (``unit``; current × ``torque_constant``), go from the motor side to
   the joint side (``side: motor``: q = R⁻¹ m for positions, τ = Rᵀ c for torques, with
   motor = R · joint), then ``scale`` and ``offset``;
3. at the file's own rate: derive qd, qdd from q and low-pass what ``filter`` names (a jittered
   series is first put on a uniform grid at its median rate, linearly);
4. read every stream at the clock's times with the stated interpolation, never across a gap
   longer than ``max_gap_s`` and never outside the span all streams cover (the log is cut to it);
5. keep the ``window``.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from diegocal.errors import LogFormatError
from diegocal.io.importers.clocks import align_sources
from diegocal.io.importers.labels import strip_subject, unprefixed
from diegocal.io.importers.mapping import (
    MOCAP_KINDS,
    STREAMS,
    Clock,
    ImportMap,
    MapError,
    StreamSpec,
    number,
    per_channel,
)
from diegocal.io.importers.robot_info import (
    RobotInfo,
    check_marker_names,
    fold_mimic,
    robot_attribute,
    robot_info,
    unit_text,
)
from diegocal.io.importers.signals import (
    default_max_gap,
    derivatives,
    excitation_window,
    is_uniform,
    lowpass,
    resample,
    uniform_grid,
    uniform_rate,
)
from diegocal.io.importers.sources import open_sources
from diegocal.io.importers.tables import DIEGOCAL, JOINT_STATE, POINTS, Source, Table, preview
from diegocal.io.importers.units import UnitError, check_joint_unit, close_match, factor, is_current, target_unit
from diegocal.io.log import JOINT_STREAMS, NAN_ALLOWED, VECTOR_STREAMS, Log, make_stream

#: Which JointState field gives which stream.
_JOINT_STATE_FIELD = {"q": "position", "qd": "velocity", "tau": "effort"}
_POSITION_LIKE = ("q", "qd", "qdd")
_AXES = (("x", "y", "z"), ("X", "Y", "Z"))


@dataclass(frozen=True)
class Series:
    """One stream on its file's time stamps, before alignment. data: (T, K) or (T, K, 3)."""

    stream: str
    names: tuple[str, ...]
    time: np.ndarray
    data: np.ndarray
    origin: str  # "source[/table]" for messages
    source: str
    table: str
    max_gap_s: float
    rate_hz: float | None = None  # set once the series is uniform


@dataclass(frozen=True)
class ImportResult:
    """An imported log and, in words, what the import did (for the summary)."""

    log: Log
    sources: tuple[tuple[str, str, str], ...]  # (name, file, kind)
    streams: tuple[tuple[str, str, int, str], ...]  # (stream, "from <file>", channels, conversion)
    clock: str
    notes: tuple[str, ...]
    offsets: tuple = ()  # OffsetEstimate per file against the reference file (.clocks)


def import_log(paths, mapping: ImportMap | None = None, rate_hz: float | None = None,
               robot: str | None = None) -> ImportResult:
    """Read ``paths`` (CSV, C3D, ROS bags) into one log as ``mapping`` says.

    ``rate_hz`` (the CLI's ``--rate``) replaces the map's clock by a stated rate; ``robot``
    replaces its ``robot`` (when it can be found, joint units, mimic joints and marker names are
    checked against it: :mod:`.robot_info`). Raises one-line :class:`MapError` / :class:`LogFormatError` /
    :class:`InputFileError` for anything that does not fit.
    """
    mapping = mapping or ImportMap()
    if rate_hz is not None:
        mapping = replace(mapping, clock=Clock(rate_hz=rate_hz))
    sources = {s.name: s for s in open_sources(paths, mapping)}
    info = robot_info(robot or mapping.robot)
    notes: list[str] = []
    specs = mapping.streams or _default_specs(sources, notes)
    series, rows = [], []
    for spec in specs:
        s, conversion = _extract(spec, sources, mapping, info)
        series.append(s)
        if _filtered(mapping, s.stream):
            conversion += f", low-passed {mapping.filter.cutoff_hz:g} Hz"
        rows.append((s.stream, f"from {s.origin}", len(s.names), conversion))
    for src in sources.values():
        for table in src.loaded():
            notes.extend(table.notes)
    series, offsets = align_sources(series, sources, mapping.clock.source if mapping.clock else None, notes)
    series = _process(series, mapping, notes)
    time, clock_rate, clock_text = _clock(series, sources, mapping)
    streams = {}
    for s in series:
        data = resample(s.data, s.time, time, mapping.interpolation, s.max_gap_s)
        if s.stream not in NAN_ALLOWED:
            _check_finite(s, data, time)
        streams[s.stream] = make_stream(s.names, data)
    streams = fold_mimic(streams, info, notes)
    if "markers" in streams:
        check_marker_names(streams["markers"].names, info)
    time, streams = _window(time, streams, clock_rate, mapping, notes)
    ordered = {k: streams[k] for k in STREAMS if k in streams}
    log = Log(time=np.ascontiguousarray(time), streams=ordered, robot=robot_attribute(robot or mapping.robot),
              rate_hz=clock_rate)
    return ImportResult(
        log=log,
        sources=tuple((s.name, str(s.path), s.kind) for s in sources.values()),
        streams=tuple(sorted(rows, key=lambda r: STREAMS.index(r[0]))) + tuple(
            (d, "derived from q", len(streams["q"].names), _filter_text(mapping, d, streams["q"].names, info))
            for d in mapping.derive
            if d in ordered),
        clock=clock_text,
        notes=tuple(notes),
        offsets=tuple(offsets),
    )


# ----------------------------------------------------------------------------- 1. channels
def _default_specs(sources: dict[str, Source], notes: list[str]) -> tuple[StreamSpec, ...]:
    """Every file's natural streams, when the map names none."""
    specs, origin = [], {}
    for src in sources.values():
        found = []
        if src.kind in MOCAP_KINDS:
            found.append(StreamSpec("markers", source=src.name, table=src.default_table))
            others = [t for t in src.table_names if t != src.default_table]
            if others:
                notes.append(f"{src.path.name}: {', '.join(others)} not imported (map them to a stream)")
        else:
            if src.kind == "bag":
                js = [t for t in src.table_names if t == src.default_table]
                others = [t for t in src.table_names if t not in js]
                if not js:
                    raise MapError(f"{src.path.name}: no single sensor_msgs/JointState topic to import "
                                   f"(topics: {', '.join(src.table_names)}); map the streams with --map")
                if others:
                    notes.append(f"{src.path.name}: topics not imported: {', '.join(others)}")
            table = src.table(None)
            if table.kind == JOINT_STATE:
                prefixes = {c.split(".", 1)[0] for c in table.columns}
                found += [StreamSpec(st, source=src.name, table=table.name)
                          for st, f in _JOINT_STATE_FIELD.items() if f in prefixes]
            elif table.kind == DIEGOCAL:
                found += [StreamSpec(st, source=src.name, table=table.name)
                          for st in STREAMS if any(c.startswith(st + ".") for c in table.columns)]
            else:
                _misspelt_stream(src, table)
                raise MapError(f"{src.path.name}: nothing to import without a map (columns: "
                               f"{preview(list(table.columns))}); map them to streams with --map")
        for spec in found:
            if spec.stream in origin:
                raise MapError(f"stream '{spec.stream}' comes from both {origin[spec.stream]} and "
                               f"{src.path.name}; say which with `streams:` in a map")
            origin[spec.stream] = src.path.name
            specs.append(spec)
    return tuple(specs)


def _misspelt_stream(src: Source, table: Table) -> None:
    """A diegocal-style column whose stream is misspelt (``tua.joint2``): say so, with the close match."""
    for col in table.columns:
        prefix = col.split(".", 1)[0]
        hint = close_match(prefix, STREAMS) if "." in col and prefix not in STREAMS else ""
        if hint:
            raise MapError(f"{src.path.name}: column {col!r} names no stream ({prefix!r}){hint} "
                           f"(streams: {', '.join(STREAMS)})")


def _extract(spec: StreamSpec, sources: dict[str, Source], mapping: ImportMap,
             info: RobotInfo | None) -> tuple[Series, str]:
    """The stream's channels from one table, converted to the log's units on the joint side."""
    if spec.source is None:
        if len(sources) != 1:
            raise MapError(f"stream '{spec.stream}': name its `source:` (sources: {', '.join(sources)})")
        src = next(iter(sources.values()))
    else:
        if spec.source not in sources:
            raise MapError(f"stream '{spec.stream}': no source {spec.source!r}" + close_match(spec.source, sources))
        src = sources[spec.source]
    table = src.table(spec.table)
    origin = _label(src, table)
    where = f"stream '{spec.stream}' ({origin})"
    pairs = spec.columns if spec.columns is not None else _natural(spec.stream, table, where)
    subject = ""
    if spec.stream == "markers":  # `ua1` in the map for Vicon's `PR2:ua1`; one subject's prefix off the names
        pairs = tuple((c if c in table.columns else unprefixed(c, table.columns) or c, ch) for c, ch in pairs)
        if spec.subject is not None or spec.columns is None:
            pairs, subject = strip_subject(pairs, spec.subject, where)
    names = tuple(ch for _, ch in pairs)
    cols = [_column(spec.stream, table, col, where) for col, _ in pairs]
    vector = spec.stream in VECTOR_STREAMS
    for (col, _), c in zip(pairs, cols, strict=True):
        if (c.ndim == 2) != vector:
            raise MapError(f"{where}: column {col!r} is " + ("a marker (x, y, z); only markers take it" if c.ndim == 2
                                                               else "a single number, a marker needs x, y, z"))
    data = np.stack(cols, axis=1).astype(np.float64)
    data, conversion = _convert(spec, data, names, [c for c, _ in pairs], table, mapping, where, info)
    if subject:
        conversion += f", {subject}"
    max_gap = src.spec.max_gap_s if src.spec.max_gap_s is not None else default_max_gap(table.time)
    time = table.time + spec.time_offset if spec.time_offset else table.time
    if spec.time_offset:
        conversion += f", time {spec.time_offset:+g} s"
    return Series(spec.stream, names, time, data, origin, src.name, table.name, max_gap,
                  table.rate_hz), conversion


def _label(src: Source, table: Table) -> str:
    """The file name, and the topic for a bag: where a stream came from, in messages."""
    return src.path.name + (f" {table.name}" if src.kind == "bag" else "")


def _natural(stream: str, table: Table, where: str) -> tuple[tuple[str, str], ...]:
    if table.kind == JOINT_STATE and stream in _JOINT_STATE_FIELD:
        field = _JOINT_STATE_FIELD[stream]
        pairs = tuple((c, c.split(".", 1)[1]) for c in table.columns if c.startswith(field + "."))
        if not pairs:
            raise MapError(f"{where}: the JointState messages carry no {field}")
        return pairs
    if table.kind == POINTS and stream == "markers":
        return tuple((c, c) for c in table.columns)
    if table.kind == DIEGOCAL:
        pairs = tuple((c, c.split(".", 1)[1]) for c in table.columns if c.startswith(stream + "."))
        if pairs:
            return pairs
    raise MapError(f"{where}: name its columns in the map (columns: {{file column: channel}}); the table has "
                   f"{preview(list(table.columns))}")


def _column(stream: str, table: Table, col: str, where: str) -> np.ndarray:
    """A column by its file name, or by the channel part of a natural name (``position.<col>``),
    or a marker from ``<col>.x|y|z`` / ``<col>_x|y|z`` columns."""
    if col in table.columns:
        return table.columns[col]
    prefixes = [_JOINT_STATE_FIELD.get(stream)] if table.kind == JOINT_STATE else [stream]
    for p in prefixes:
        if p and f"{p}.{col}" in table.columns:
            return table.columns[f"{p}.{col}"]
    if stream in VECTOR_STREAMS:
        for sep in (".", "_", " "):
            for axes in _AXES:
                names = [f"{col}{sep}{a}" for a in axes]
                if all(n in table.columns for n in names):
                    return np.stack([table.columns[n] for n in names], axis=1)
    return table.column(col, where)  # raises with a close match


def _header_unit(spec: StreamSpec, unit: str | None, name: str, info: RobotInfo | None) -> str | None:
    """A column name's unit (``elbow [mV]``) where the map states no unit (nor a scale: the
    caller) and it fits the stream (a voltage for pots; a joint's family): else None, the name's
    brackets a label (``knee (A)``)."""
    if unit is None:
        return None
    if spec.stream == "pots":
        return unit if target_unit("pots", unit) == "V" else None
    try:
        factor(spec.stream, unit)
        if info is not None and spec.side == "joint":
            check_joint_unit(spec.stream, unit, name, info.kind(name))
    except UnitError:
        return None
    return unit


def _convert(spec: StreamSpec, data, names, cols, table: Table, mapping: ImportMap, where: str,
             info: RobotInfo | None):
    """Units, torque constant, transmission, scale, offset (in this order); returns data, words."""
    stream = spec.stream
    units = per_channel(spec.unit, names, None, f"{where}: unit")
    scaled = [number(v, f"{where}: scale") != 1.0 for v in per_channel(spec.scale, names, 1.0, f"{where}: scale")]
    words, targets, converted = [], [], False
    for k, unit in enumerate(units):
        if unit is None:
            header = None if scaled[k] else table.header_units.get(cols[k])  # a map's scale rules
            unit = table.units.get(cols[k]) or _header_unit(spec, header, names[k], info)
            if unit is None:
                if stream == "markers":
                    raise MapError(f"{where}: the file states no unit for marker {names[k]!r}; "
                                   "give `unit:` (m, cm or mm) in the map")
                continue  # the log's unit already (ROS: SI)
        if info is not None and spec.side == "joint":
            check_joint_unit(stream, unit, names[k], info.kind(names[k]))
        f = factor(stream, unit)
        if is_current(stream, unit):
            kt = per_channel(spec.torque_constant, names, None, f"{where}: torque_constant")[k]
            if kt is None:
                raise MapError(f"{where}: channel {names[k]!r} is in {unit}: give `torque_constant` (N·m/A)")
            f *= number(kt, f"{where}: torque_constant")
        if f != 1.0:
            data[:, k] = data[:, k] * f
            converted = True
        words.append(unit)
        targets.append(target_unit(stream, unit))
    log_unit = unit_text(stream, names, info) if stream != "pots" else "/".join(dict.fromkeys(targets))
    text = "/".join(dict.fromkeys(words)) or log_unit
    if words and (converted or info is not None and stream in JOINT_STREAMS):  # say what the units became
        text += f" -> {log_unit}"
    if spec.side == "motor":
        ratio = mapping.ratio
        if ratio is None:
            raise MapError(f"{where}: side: motor needs `transmission: ratio:` in the map")
        if stream not in JOINT_STREAMS:
            raise MapError(f"{where}: only joint streams (q, qd, qdd, tau) go through a transmission")
        if ratio.shape[0] != len(names):
            raise MapError(f"{where}: the transmission ratio is {ratio.shape[0]}x{ratio.shape[0]} for "
                           f"{len(names)} channels")
        # motor = R · joint: positions q = R⁻¹ m; torques by virtual work τ = Rᵀ c
        data = np.linalg.solve(ratio, data.T).T if stream in _POSITION_LIKE else data @ ratio
        text += ", motor -> joint side"
    scale = np.array([number(v, f"{where}: scale") for v in per_channel(spec.scale, names, 1.0, f"{where}: scale")])
    offset = np.array([number(v, f"{where}: offset")
                       for v in per_channel(spec.offset, names, 0.0, f"{where}: offset")])
    if (scale != 1.0).any():
        data = data * (scale[:, None] if data.ndim == 3 else scale)
        text += ", scaled"
    if (offset != 0.0).any():
        data = data + (offset[:, None] if data.ndim == 3 else offset)
        text += ", offset"
    return data, text


# ----------------------------------------------------------------------------- 3. filter, derive
def _filtered(mapping: ImportMap, stream: str) -> bool:
    """Whether the map's filter acts on ``stream`` (by default on every joint stream)."""
    filt = mapping.filter
    return filt is not None and stream in (filt.streams if filt.streams is not None else JOINT_STREAMS)


def _process(series: list[Series], mapping: ImportMap, notes: list[str]) -> list[Series]:
    filt = mapping.filter
    targets = set(filt.streams) if filt and filt.streams is not None else set(JOINT_STREAMS)
    by_stream = {s.stream: s for s in series}
    if mapping.derive and "q" not in by_stream:
        raise MapError(f"derive: {', '.join(mapping.derive)} need a q stream")
    if filt is not None:
        for name in targets:
            if name not in by_stream and name not in mapping.derive and filt.streams is not None:
                raise MapError(f"filter: no stream {name!r} to filter" + close_match(name, by_stream))
    out = []
    for s in series:
        wants_filter = filt is not None and s.stream in targets
        derive = s.stream == "q" and bool(mapping.derive)
        if not (wants_filter or derive):
            out.append(s)
            continue
        s = _uniform(s, notes)
        if derive:
            qf, qd, qdd = derivatives(s.data, s.rate_hz, filt.cutoff_hz if filt else None,
                                      filt.order if filt else 4)
            extra = {"qd": qd, "qdd": qdd}
            out.extend(replace(s, stream=d, data=extra[d], origin="derived from q") for d in mapping.derive)
            if wants_filter:
                s = replace(s, data=qf)
        elif wants_filter:
            s = replace(s, data=lowpass(s.data, s.rate_hz, filt.cutoff_hz, filt.order))
        out.append(s)
    return out


def _uniform(s: Series, notes: list[str]) -> Series:
    """The series on a uniform grid (as is when already uniform), its rate set; NaN refused."""
    if not np.isfinite(s.data).all():
        raise LogFormatError(f"stream '{s.stream}' ({s.origin}): NaN in the file's values; "
                             "a stream with gaps cannot be filtered or differentiated")
    if is_uniform(s.time):
        rate = s.rate_hz or (s.time.shape[0] - 1) / (s.time[-1] - s.time[0])
        return replace(s, rate_hz=float(rate))
    rate = uniform_rate(s.time)
    grid = uniform_grid(s.time[0], s.time[-1], rate)
    data = resample(s.data, s.time, grid, "linear", s.max_gap_s)
    _check_finite(s, data, grid)
    notes.append(f"{s.stream} ({s.origin}): jittered time stamps put on a uniform {rate:g} Hz grid (linear) "
                 "before filtering")
    return replace(s, time=grid, data=data, rate_hz=rate)


def _filter_text(mapping: ImportMap, stream: str, names, info: RobotInfo | None) -> str:
    filt = mapping.filter
    base = f"central differences, {unit_text(stream, names, info)}"
    if filt is None:
        return base + ", unfiltered"
    return base + f", low-passed {filt.cutoff_hz:g} Hz"


# ----------------------------------------------------------------------------- 4. clock
def _clock(series: list[Series], sources: dict[str, Source], mapping: ImportMap):
    """(time (N,), rate or None, words): the clock's times inside the span every stream covers."""
    start = max(s.time[0] for s in series)
    stop = min(s.time[-1] for s in series)
    if start > stop:
        spans = "; ".join(f"{s.stream} {s.time[0]:.6g}..{s.time[-1]:.6g} s" for s in series)
        raise MapError(f"the streams do not overlap in time ({spans}); align the files' clocks with "
                       "time_offset or zero_time in the map")
    clock = mapping.clock
    if clock is not None and clock.rate_hz is not None:
        time, rate, text = uniform_grid(start, stop, clock.rate_hz), clock.rate_hz, f"{clock.rate_hz:g} Hz (stated)"
    else:
        table = _clock_table(series, sources, clock)
        time = table.time[(table.time >= start) & (table.time <= stop)]
        rate = table.rate_hz
        if rate is None and is_uniform(table.time) and table.time.shape[0] > 1:
            rate = float(uniform_rate(table.time))
        text = f"{table.origin}'s time stamps" + (f" ({rate:g} Hz)" if rate else "")
    if time.shape[0] < 2:
        raise MapError(f"the streams overlap for {stop - start:.3g} s only: fewer than 2 samples on the clock")
    kept = "" if (start, stop) == (min(s.time[0] for s in series), max(s.time[-1] for s in series)) else (
        f"; cut to {start:.6g}..{stop:.6g} s, the span every stream covers")
    return time, rate, text + f", {mapping.interpolation} interpolation" + kept


def _same_stamps(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether two tables' time stamps are one clock: equal within a thousandth of a sample period
    (a column in ms and one in s differ by the conversion's rounding)."""
    if a.shape != b.shape:
        return False
    step = float(np.median(np.diff(b))) if b.size > 1 else 0.0
    return bool(np.allclose(a, b, rtol=0.0, atol=1e-3 * abs(step)))


@dataclass(frozen=True)
class _ClockTable:
    time: np.ndarray
    rate_hz: float | None
    origin: str


def _clock_table(series: list[Series], sources: dict[str, Source], clock: Clock | None) -> _ClockTable:
    if clock is not None:  # a named source (and table)
        if clock.source not in sources:
            raise MapError(f"clock: no source {clock.source!r}" + close_match(clock.source, sources))
        src = sources[clock.source]
        t = src.table(clock.table)
        return _ClockTable(t.time, t.rate_hz, _label(src, t))
    mocap = {(s.source, s.table) for s in series if sources[s.source].kind in MOCAP_KINDS and s.stream == "markers"}
    if len(mocap) == 1:
        s = next(x for x in series if (x.source, x.table) in mocap)
        return _ClockTable(s.time, s.rate_hz, sources[s.source].path.name)
    first = series[0]
    if len({(s.source, s.table) for s in series}) == 1:  # one table: its own time stamps
        src = sources[first.source]
        t = src.table(first.table)
        return _ClockTable(t.time, t.rate_hz, _label(src, t))
    if all(_same_stamps(s.time, first.time) for s in series):
        return _ClockTable(first.time, first.rate_hz, first.origin)
    rates = ", ".join(f"{s.stream} {_rate_text(s.time)}" for s in series)
    raise MapError(f"the streams have different clocks ({rates}): choose one with --rate HZ or `clock:` "
                   "in the map (rate_hz, or the source whose time stamps to use)")


def _rate_text(t: np.ndarray) -> str:
    return f"~{1.0 / float(np.median(np.diff(t))):.4g} Hz" if t.shape[0] > 1 else "1 sample"


def _check_finite(s: Series, data: np.ndarray, time: np.ndarray) -> None:
    """A stream that may not hold NaN: say whether a gap in the file or a NaN value caused it."""
    bad = ~np.isfinite(data.reshape(data.shape[0], -1)).all(axis=1)
    if not bad.any():
        return
    i = int(np.argmax(bad))
    k = int(np.searchsorted(s.time, time[i], side="right"))
    if 0 < k < s.time.shape[0] and s.time[k] - s.time[k - 1] > s.max_gap_s:
        raise LogFormatError(
            f"stream '{s.stream}' ({s.origin}): no sample for {s.time[k] - s.time[k - 1]:.3g} s after "
            f"t = {s.time[k - 1]:.6g} s, longer than max_gap_s = {s.max_gap_s:.3g} s; set max_gap_s for this "
            "source in the map to interpolate across it")
    raise LogFormatError(f"stream '{s.stream}' ({s.origin}): NaN or empty value near t = {time[i]:.6g} s; "
                         "only markers may have gaps")


# ----------------------------------------------------------------------------- 5. window
def _window(time, streams, rate, mapping: ImportMap, notes: list[str]):
    w = mapping.window
    if w is None:
        return time, streams
    if w.auto:
        if "qd" not in streams:
            raise MapError("window: auto finds the motion from qd: derive it or map it")
        rate = rate or 1.0 / float(np.median(np.diff(time)))
        start, stop = excitation_window(streams["qd"].data, rate, w.threshold, w.margin_s)
        notes.append(f"window: kept {time[start]:.6g}..{time[stop - 1]:.6g} s, where a joint moves faster "
                     f"than {w.threshold:g} rad/s (m/s), ± {w.margin_s:g} s")
    else:
        start, stop = (int(i) for i in np.searchsorted(time, [w.start, w.stop]))
        if stop - start < 2:
            raise MapError(f"window [{w.start:g}, {w.stop:g}] s holds fewer than 2 samples "
                           f"(the log spans {time[0]:.6g}..{time[-1]:.6g} s)")
    cut = {k: make_stream(s.names, s.data[start:stop]) for k, s in streams.items()}
    return time[start:stop], cut

