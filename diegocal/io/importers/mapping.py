"""The import map: a small YAML file saying which file columns become which log channels.

Every key is optional; without a map each file gives its natural streams (a C3D its markers,
a ``sensor_msgs/JointState`` topic or ``rostopic echo -p`` CSV its q, qd and tau, a diegocal CSV
its ``<stream>.<name>`` columns)::

    robot: tx40                       # the log's robot attribute
    sources:                          # name -> how to read one SRC file
      pos:
        file: pos_read_data.csv       # matched against the SRC file names (shell pattern)
        rate_hz: 5000                 # a CSV without a time column: sample k at k / rate_hz s
        # time: t, time_unit: s       # a CSV's time column and its unit (s, ms, us, ns)
        # time_offset: 0.0            # s, added to this file's time stamps (align two clocks);
        #                             # auto: estimated from the motion both files record
        # zero_time: false            # subtract the file's first time stamp first
        # stamp: header               # bags: header stamps (receive time where a header is 0) | receive
        # max_gap_s: 0.05             # no interpolation across longer gaps [10 sample periods]
        # allow_truncated: false      # C3D cut short: keep the frames read, with a warning
    streams:                          # only these streams are imported when given
      q:
        source: pos                   # [the only source]
        # table: /joint_states        # a bag topic, or points | analogs of a C3D
        columns: {Joint_1: joint_1}   # file column -> channel name (a list keeps the names)
        unit: rad                     # or {channel: unit, '*': unit for the rest}
        side: motor                   # motor-side values, through `transmission`
        offset: [0, -1.5708]          # value = scale * x + offset, last; number, list or mapping
        # scale: 1.0
        # torque_constant: 0.1        # N·m/A, for tau in A or mA
        # time_offset: 0.0            # s, added to this stream's time stamps (after its source's)
      # markers: {subject: PR2}       # Vicon/Motive Subject:Marker labels: keep this subject's
    transmission:                     # motor = ratio · joint (rows: motors, columns: joints)
      ratio: [[32, 0], [0, 45]]       # or a list: the diagonal
    clock: {rate_hz: 200}             # or {source: mocap} [the C3D's, else the only file's]
    interpolation: linear             # linear | nearest | previous
    filter: {cutoff_hz: 10, order: 4} # zero-phase Butterworth [on q, qd, qdd, tau]
    derive: [qd, qdd]                 # from q: central differences, each low-passed again
    window: auto                      # auto (where qd moves) | [t0, t1] in s | {threshold, margin_s}

Errors are one line naming the key, with a close match for a misspelt name (difflib).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from diegocal.errors import DiegocalError
from diegocal.io.files import load_yaml
from diegocal.io.importers.units import STREAM_UNITS, close_match

#: Streams a log may hold (DESIGN.md), in the order a log lists them.
STREAMS = tuple(STREAM_UNITS)
DERIVABLE = ("qd", "qdd")
INTERPOLATIONS = ("linear", "nearest", "previous")
SOURCE_KINDS = ("csv", "c3d", "bag", "trc", "vicon", "motive")
#: Source kinds that are motion capture: their marker table is a natural stream and their clock is
#: the one a log takes by default.
MOCAP_KINDS = ("c3d", "trc", "vicon", "motive")


class MapError(DiegocalError, ValueError):
    """An import map (or the files it is applied to) does not fit together."""


@dataclass(frozen=True)
class SourceSpec:
    """How to read one SRC file (see the module docstring for each key)."""

    name: str
    file: str | None = None
    kind: str | None = None
    time: str | None = None
    time_unit: str | None = None
    rate_hz: float | None = None
    time_offset: float = 0.0
    zero_time: bool = False
    stamp: str = "header"
    max_gap_s: float | None = None
    allow_truncated: bool = False
    auto_offset: bool = False  # `time_offset: auto`: estimated from the motion (see .clocks)


@dataclass(frozen=True)
class StreamSpec:
    """Which columns of which table make one log stream, and how their values convert.

    ``columns``: (file column, channel) pairs, or None for the table's natural channels.
    ``unit``, ``scale``, ``offset``, ``torque_constant``: a number/name, a list (per channel) or
    a mapping channel -> value with '*' for the rest; resolved once the channels are known.
    """

    stream: str
    source: str | None = None
    table: str | None = None
    columns: tuple[tuple[str, str], ...] | None = None
    unit: object = None
    side: str = "joint"
    scale: object = 1.0
    offset: object = 0.0
    torque_constant: object = None
    subject: str | None = None
    time_offset: float = 0.0


@dataclass(frozen=True)
class Clock:
    """The output time base: a stated rate (Hz), or the time stamps of one source's table."""

    rate_hz: float | None = None
    source: str | None = None
    table: str | None = None


@dataclass(frozen=True)
class FilterSpec:
    """Zero-phase Butterworth low-pass (``scipy.signal.sosfiltfilt``): cut-off Hz, order of one pass."""

    cutoff_hz: float
    order: int = 4
    streams: tuple[str, ...] | None = None  # None: every joint stream (q, qd, qdd, tau)


@dataclass(frozen=True)
class Window:
    """Which part of the aligned log to keep: [start, stop) s, or where any joint moves."""

    auto: bool = False
    threshold: float = 0.02  # rad/s (m/s)
    margin_s: float = 0.25
    start: float | None = None
    stop: float | None = None


@dataclass(frozen=True)
class ImportMap:
    """A parsed import map; :func:`load_map` reads one, ``ImportMap()`` is the empty map."""

    robot: str | None = None
    sources: tuple[SourceSpec, ...] = ()
    streams: tuple[StreamSpec, ...] = ()
    ratio: np.ndarray | None = field(default=None, compare=False)
    clock: Clock | None = None
    interpolation: str = "linear"
    filter: FilterSpec | None = None
    derive: tuple[str, ...] = ()
    window: Window | None = None
    path: str | None = None

    def source(self, name: str) -> SourceSpec:
        for s in self.sources:
            if s.name == name:
                return s
        names = [s.name for s in self.sources]
        raise MapError(f"{self._where()}no source {name!r} (sources: {', '.join(names) or 'none'})"
                       + close_match(name, names))

    def _where(self) -> str:
        return f"{self.path}: " if self.path else ""


# ----------------------------------------------------------------------------- parsing
_TOP = ("robot", "sources", "streams", "transmission", "clock", "interpolation", "filter", "derive", "window")
_SOURCE = ("file", "kind", "time", "time_unit", "rate_hz", "time_offset", "zero_time", "stamp", "max_gap_s",
           "allow_truncated")
_STREAM = ("source", "table", "columns", "unit", "side", "scale", "offset", "torque_constant", "subject",
           "time_offset")


def load_map(path) -> ImportMap:
    """Read and check an import map (YAML); one :class:`MapError` line when it is wrong."""
    path = Path(path)
    out = parse_map(load_yaml(path), where=str(path))
    robot = Path(out.robot) if out.robot else None
    if robot is not None and not robot.is_absolute() and not robot.exists() and ("/" in out.robot or robot.suffix):
        if (path.parent / robot).exists():  # a robot path (not a bundled name) read from the map's folder
            out = replace(out, robot=str(path.parent / robot))
    return out


def parse_map(data: dict, where: str | None = None) -> ImportMap:
    """An :class:`ImportMap` from the YAML mapping ``data``."""
    pre = f"{where}: " if where else ""
    if not isinstance(data, dict):
        raise MapError(f"{pre}expected a mapping at the top level")
    _known_keys(data, _TOP, pre + "unknown key")
    sources = tuple(_source(name, spec, pre) for name, spec in _mapping(data.get("sources"), pre + "sources").items())
    streams = tuple(_stream(name, spec, pre) for name, spec in _mapping(data.get("streams"), pre + "streams").items())
    interpolation = str(data.get("interpolation", "linear"))
    if interpolation not in INTERPOLATIONS:
        raise MapError(f"{pre}interpolation {interpolation!r} is not one of {', '.join(INTERPOLATIONS)}"
                       + close_match(interpolation, INTERPOLATIONS))
    derive = tuple(str(d) for d in _list(data.get("derive", []), pre + "derive"))
    for d in derive:
        if d not in DERIVABLE:
            raise MapError(f"{pre}derive: {d!r} cannot be derived (only qd, qdd, from q)" + close_match(d, DERIVABLE))
    mapped = {s.stream for s in streams}
    if set(derive) & mapped:
        raise MapError(f"{pre}{sorted(set(derive) & mapped)[0]} is both mapped from a file and derived; keep one")
    out = ImportMap(
        robot=None if data.get("robot") is None else str(data["robot"]),
        sources=sources,
        streams=streams,
        ratio=_ratio(data.get("transmission"), pre),
        clock=_clock(data.get("clock"), pre),
        interpolation=interpolation,
        filter=_filter(data.get("filter"), pre),
        derive=derive,
        window=_window(data.get("window"), pre),
        path=where,
    )
    for s in streams:
        if s.source is not None:
            out.source(s.source)  # a stream's source must be declared
    if out.clock is not None and out.clock.source is not None and sources:
        out.source(out.clock.source)
    return out


def _source(name, spec, pre) -> SourceSpec:
    if isinstance(spec, str):  # `pos: pos_read_data.csv`
        spec = {"file": spec}
    spec = _mapping(spec, f"{pre}source {name!r}")
    _known_keys(spec, _SOURCE, f"{pre}source {name!r}: unknown key")
    kind = spec.get("kind")
    if kind is not None and kind not in SOURCE_KINDS:
        raise MapError(f"{pre}source {name!r}: kind {kind!r} is not one of {', '.join(SOURCE_KINDS)}"
                       + close_match(kind, SOURCE_KINDS))
    stamp = str(spec.get("stamp", "header"))
    if stamp not in ("header", "receive"):
        raise MapError(f"{pre}source {name!r}: stamp must be header or receive, got {stamp!r}")
    if spec.get("time") is not None and spec.get("rate_hz") is not None:
        raise MapError(f"{pre}source {name!r}: give either a time column or rate_hz, not both")
    auto = spec.get("time_offset") == "auto"
    return SourceSpec(
        name=str(name),
        file=None if spec.get("file") is None else str(spec["file"]),
        kind=kind,
        time=None if spec.get("time") is None else str(spec["time"]),
        time_unit=None if spec.get("time_unit") is None else str(spec["time_unit"]),
        rate_hz=_positive(spec.get("rate_hz"), f"{pre}source {name!r}: rate_hz"),
        time_offset=0.0 if auto else number(spec.get("time_offset", 0.0), f"{pre}source {name!r}: time_offset"),
        auto_offset=auto,
        zero_time=bool(spec.get("zero_time", False)),
        stamp=stamp,
        max_gap_s=_positive(spec.get("max_gap_s"), f"{pre}source {name!r}: max_gap_s"),
        allow_truncated=_flag(spec.get("allow_truncated", False), f"{pre}source {name!r}: allow_truncated"),
    )


def _stream(name, spec, pre) -> StreamSpec:
    name = str(name)
    if name not in STREAMS:
        raise MapError(f"{pre}streams: unknown stream {name!r} (streams: {', '.join(STREAMS)})"
                       + close_match(name, STREAMS))
    where = f"{pre}stream {name!r}"
    spec = _mapping(spec, where)
    _known_keys(spec, _STREAM, f"{where}: unknown key")
    side = str(spec.get("side", "joint"))
    if side not in ("joint", "motor"):
        raise MapError(f"{where}: side must be joint or motor, got {side!r}" + close_match(side, ("joint", "motor")))
    columns = spec.get("columns")
    if columns is not None:
        if isinstance(columns, dict):
            pairs = tuple((str(k), str(v)) for k, v in columns.items())
        elif isinstance(columns, list):
            pairs = tuple((str(c), str(c)) for c in columns)
        else:
            raise MapError(f"{where}: columns must be a mapping (file column -> channel) or a list")
        if not pairs:
            raise MapError(f"{where}: columns is empty")
        channels = [c for _, c in pairs]
        if len(set(channels)) != len(channels):
            dup = sorted({c for c in channels if channels.count(c) > 1})
            raise MapError(f"{where}: channel {dup[0]!r} is mapped twice")
        columns = pairs
    return StreamSpec(
        stream=name,
        source=None if spec.get("source") is None else str(spec["source"]),
        table=None if spec.get("table") is None else str(spec["table"]),
        columns=columns,
        unit=spec.get("unit"),
        side=side,
        scale=spec.get("scale", 1.0),
        offset=spec.get("offset", 0.0),
        torque_constant=spec.get("torque_constant"),
        subject=None if spec.get("subject") is None else str(spec["subject"]),
        time_offset=number(spec.get("time_offset", 0.0), f"{where}: time_offset"),
    )


def _ratio(spec, pre) -> np.ndarray | None:
    if spec is None:
        return None
    spec = _mapping(spec, pre + "transmission")
    _known_keys(spec, ("ratio",), pre + "transmission: unknown key")
    try:
        ratio = np.asarray(spec.get("ratio"), dtype=np.float64)
    except (TypeError, ValueError):
        raise MapError(f"{pre}transmission: ratio must be a list of numbers or a square matrix") from None
    if ratio.ndim == 1:
        ratio = np.diag(ratio)
    if ratio.ndim != 2 or ratio.shape[0] != ratio.shape[1] or ratio.size == 0:
        raise MapError(f"{pre}transmission: ratio must be a list (diagonal) or a square matrix, "
                       f"got shape {ratio.shape}")
    if not np.isfinite(ratio).all() or abs(np.linalg.det(ratio)) < 1e-12:
        raise MapError(f"{pre}transmission: ratio must be finite and invertible")
    return ratio


def _clock(spec, pre) -> Clock | None:
    if spec is None:
        return None
    spec = _mapping(spec, pre + "clock")
    _known_keys(spec, ("rate_hz", "source", "table"), pre + "clock: unknown key")
    if (spec.get("rate_hz") is None) == (spec.get("source") is None):
        raise MapError(f"{pre}clock: give rate_hz or source (one of them)")
    return Clock(rate_hz=_positive(spec.get("rate_hz"), pre + "clock: rate_hz"),
                 source=None if spec.get("source") is None else str(spec["source"]),
                 table=None if spec.get("table") is None else str(spec["table"]))


def _filter(spec, pre) -> FilterSpec | None:
    if spec is None:
        return None
    spec = _mapping(spec, pre + "filter")
    _known_keys(spec, ("cutoff_hz", "order", "streams"), pre + "filter: unknown key")
    cutoff = _positive(spec.get("cutoff_hz"), pre + "filter: cutoff_hz")
    if cutoff is None:
        raise MapError(f"{pre}filter: cutoff_hz is required")
    order = spec.get("order", 4)
    if not isinstance(order, int) or not 1 <= order <= 10:
        raise MapError(f"{pre}filter: order must be an integer in 1..10, got {order!r}")
    streams = spec.get("streams")
    if streams is not None:
        streams = tuple(str(s) for s in _list(streams, pre + "filter: streams"))
        for s in streams:
            if s not in STREAMS:
                raise MapError(f"{pre}filter: unknown stream {s!r}" + close_match(s, STREAMS))
            if s == "markers":
                raise MapError(f"{pre}filter: markers cannot be filtered (occlusions leave gaps)")
    return FilterSpec(cutoff_hz=cutoff, order=order, streams=streams)


def _window(spec, pre) -> Window | None:
    if spec is None:
        return None
    if spec == "auto":
        return Window(auto=True)
    if isinstance(spec, dict):
        _known_keys(spec, ("threshold", "margin_s"), pre + "window: unknown key")
        return Window(auto=True, threshold=_positive(spec.get("threshold", 0.02), pre + "window: threshold"),
                      margin_s=number(spec.get("margin_s", 0.25), pre + "window: margin_s"))
    if isinstance(spec, list) and len(spec) == 2:
        lo, hi = (number(v, pre + "window") for v in spec)
        if not lo < hi:
            raise MapError(f"{pre}window: start {lo} s must be before stop {hi} s")
        return Window(start=lo, stop=hi)
    raise MapError(f"{pre}window must be auto, [start, stop] in s, or {{threshold, margin_s}}; got {spec!r}")


# ----------------------------------------------------------------------------- helpers
def _known_keys(spec: dict, known, what: str) -> None:
    for key in spec:
        if key not in known:
            raise MapError(f"{what} {key!r} (known: {', '.join(known)})" + close_match(key, known))


def _mapping(value, what: str) -> dict:
    if value is None:
        return {}
    if not isinstance(value, dict):
        raise MapError(f"{what}: expected a mapping, got {type(value).__name__}")
    return value


def _list(value, what: str) -> list:
    if isinstance(value, str):
        return [value]
    if not isinstance(value, list):
        raise MapError(f"{what}: expected a list, got {type(value).__name__}")
    return value


def number(value, what: str) -> float:
    """A map value as a finite float (a YAML boolean is not a number); MapError naming ``what``."""
    if isinstance(value, bool):
        raise MapError(f"{what}: expected a number, got {value!r}")
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise MapError(f"{what}: expected a number, got {value!r}") from None
    if not np.isfinite(x):
        raise MapError(f"{what}: expected a finite number, got {value!r}")
    return x


def _flag(value, what: str) -> bool:
    if not isinstance(value, bool):
        raise MapError(f"{what}: expected true or false, got {value!r}")
    return value


def _positive(value, what: str) -> float | None:
    if value is None:
        return None
    x = number(value, what)
    if x <= 0:
        raise MapError(f"{what}: expected a positive number, got {value!r}")
    return x


def per_channel(value, channels, default, what: str) -> list:
    """Resolve a per-channel setting: a scalar, a list in channel order, or a mapping with '*'."""
    n = len(channels)
    if value is None:
        return [default] * n
    if isinstance(value, dict):
        unknown = [k for k in value if k != "*" and k not in channels]
        if unknown:
            raise MapError(f"{what}: no channel {unknown[0]!r} (channels: {', '.join(channels)})"
                           + close_match(unknown[0], channels))
        rest = value.get("*", default)
        return [value.get(c, rest) for c in channels]
    if isinstance(value, list):
        if len(value) != n:
            raise MapError(f"{what}: {len(value)} values for {n} channels ({', '.join(channels)})")
        return list(value)
    return [value] * n
