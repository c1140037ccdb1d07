"""What every reader returns: time-stamped tables of named columns, one per clock in a file.

A CSV gives one table; a C3D two (``points`` at the camera rate, ``analogs`` at the analog
rate); a ROS bag one per topic. Columns are float64, samples first: (T,) for a scalar, (T, 3)
for a marker (metres or the file's length unit, NaN where occluded).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from diegocal.errors import InputFileError, LogFormatError
from diegocal.io.importers.mapping import MapError, SourceSpec
from diegocal.io.importers.units import close_match

#: Table kinds whose columns have natural streams (used when the map names no columns).
JOINT_STATE = "joint_state"  # columns position.<joint>, velocity.<joint>, effort.<joint>
POINTS = "points"  # C3D markers: columns are labels, each (T, 3)
DIEGOCAL = "diegocal"  # CSV columns <stream>.<name> (DESIGN.md's CSV layout)
GENERIC = "generic"


@dataclass(frozen=True)
class Table:
    """Columns sampled at one set of time stamps.

    Attributes
    ----------
    name : str, the table's name in its source ('' for a CSV, a topic, 'points' / 'analogs')
    time : ndarray of shape (T,), s, strictly increasing
    columns : dict of str -> ndarray of shape (T,) or (T, 3)
    kind : str, one of JOINT_STATE, POINTS, DIEGOCAL, GENERIC
    units : dict of str -> str, units the file declares per column (C3D), else empty
    rate_hz : float or None, the nominal rate the file declares (C3D, CSV ``rate_hz``)
    notes : tuple of str, what the reader did (sorted time stamps, dropped duplicates)
    header_units : dict of str -> str, a unit a lab table's column name ends in (``elbow [mV]``):
        taken only where the map states no unit and no scale and it fits the stream it feeds
    """

    name: str
    time: np.ndarray
    columns: dict
    kind: str = GENERIC
    units: dict = field(default_factory=dict)
    rate_hz: float | None = None
    notes: tuple[str, ...] = ()
    header_units: dict = field(default_factory=dict)

    def column(self, name: str, where: str) -> np.ndarray:
        if name in self.columns:
            return self.columns[name]
        raise MapError(f"{where}: no column {name!r} (has {preview(list(self.columns))})"
                       + close_match(name, self.columns))


@dataclass
class Source:
    """One SRC file: its spec, kind and tables (loaded on first use; bags read only the topics asked)."""

    spec: SourceSpec
    path: Path
    kind: str
    table_names: tuple[str, ...]
    loader: Callable[[str], Table]
    default_table: str | None = None
    _cache: dict = field(default_factory=dict)

    @property
    def name(self) -> str:
        return self.spec.name

    def table(self, name: str | None) -> Table:
        """The named table (the default one when None), read on first use."""
        if name is None:
            name = self._default()
        if name not in self.table_names:
            raise MapError(f"source {self.name!r} ({self.path.name}) has no table {name!r} "
                           f"(has {preview(self.table_names)})" + close_match(name, self.table_names))
        if name not in self._cache:
            self._cache[name] = self.loader(name)
        return self._cache[name]

    def loaded(self) -> list[Table]:
        """The tables read so far."""
        return list(self._cache.values())

    def _default(self) -> str:
        if self.default_table is not None:
            return self.default_table
        if len(self.table_names) == 1:
            return self.table_names[0]
        raise MapError(f"source {self.name!r} ({self.path.name}) has several tables "
                       f"({preview(self.table_names)}): name one with `table:` in the map")


# ----------------------------------------------------------------------------- helpers for readers
def kind_of(path: Path, spec: SourceSpec) -> str:
    """csv | c3d | bag, from the map's ``kind`` or the file name."""
    if spec.kind is not None:
        return spec.kind
    suffix = path.suffix.lower()
    if suffix == ".c3d":
        return "c3d"
    if suffix == ".trc":
        return "trc"
    if suffix in (".bag", ".db3", ".mcap") or (path.is_dir() and (path / "metadata.yaml").exists()):
        return "bag"
    if suffix in (".csv", ".txt", ".tsv"):
        return "csv"
    raise InputFileError(f"{path}: unknown source format (expected .c3d, .trc, .bag, .db3, .mcap, "
                         "a ROS 2 bag folder or .csv; or state `kind:` in the map)")


def finish_time(time: np.ndarray, spec: SourceSpec, t0: float, rel: np.ndarray | None = None) -> np.ndarray:
    """Apply ``zero_time`` (relative to the file's first stamp ``t0``, s) and ``time_offset``.

    ``rel``: the same times relative to ``t0`` computed exactly (from integer nanoseconds), used
    for ``zero_time``: ROS stamps near 1.7e9 s only resolve 0.24 µs as float64 seconds.
    """
    if spec.zero_time:
        time = rel if rel is not None else time - t0
    if spec.time_offset:
        time = time + spec.time_offset
    return time


def sort_unique(time: np.ndarray, values: list, where: str) -> tuple[np.ndarray, list, tuple[str, ...]]:
    """Sort samples by time and drop repeated stamps (first kept); notes say what changed."""
    notes = []
    if time.size and not np.isfinite(time).all():
        raise LogFormatError(f"{where}: NaN or infinite time stamp")
    order = np.argsort(time, kind="stable")
    if (np.diff(order) < 0).any():
        notes.append(f"{where}: time stamps out of order; sorted")
    time = time[order]
    values = [v[order] for v in values]
    keep = np.concatenate([[True], np.diff(time) > 0]) if time.size else np.zeros(0, bool)
    if not keep.all():
        notes.append(f"{where}: {int((~keep).sum())} repeated time stamps dropped (first kept)")
        time = time[keep]
        values = [v[keep] for v in values]
    return time, values, tuple(notes)


def check_increasing(time: np.ndarray, where: str, repeats: bool = False) -> None:
    """One error line unless ``time`` increases (or, with ``repeats``, never decreases): the row
    (the first data row is 1) and both stamps in full, so that the rows can be found."""
    if time.size == 0:
        raise LogFormatError(f"{where}: no samples")
    if not np.isfinite(time).all():
        raise LogFormatError(f"{where}: NaN or infinite time stamp at row {int(np.argmin(np.isfinite(time))) + 1}")
    steps = np.diff(time)
    wrong = steps < 0 if repeats else steps <= 0
    if wrong.any():
        i = int(np.argmax(wrong))
        what = "goes back" if steps[i] < 0 else "is not strictly increasing"
        raise LogFormatError(f"{where}: time {what} at row {i + 2} ({float(time[i])!r} then {float(time[i + 1])!r})")


def preview(names, n: int = 8) -> str:
    """The first ``n`` names, comma-separated, for messages."""
    names = list(names)
    return ", ".join(names[:n]) + (", ..." if len(names) > n else "") if names else "none"


def numeric_block(rows: list[str], ncols: int, path: Path, sep: str = "\t") -> np.ndarray:
    """Text rows of numbers -> (len(rows), ncols) float64; an empty cell (an occluded marker) or a
    short row gives NaN, cells past ``ncols`` are left out, a cell holding text is an error."""
    import io

    import pandas as pd

    if not rows:
        raise LogFormatError(f"{path}: no data rows")
    whitespace = sep == "\t" and "\t" not in rows[0]
    width = max(ncols, max((len(r.split()) if whitespace else r.count(sep) + 1) for r in rows))
    try:
        frame = pd.read_csv(io.StringIO("\n".join(rows)), sep=r"\s+" if whitespace else sep, header=None,
                            names=range(width), skipinitialspace=True)
    except (pd.errors.ParserError, ValueError) as exc:
        raise LogFormatError(f"{path}: cannot parse the data rows ({str(exc).splitlines()[0]})") from None
    frame = frame.iloc[:, :ncols]
    values = frame.apply(pd.to_numeric, errors="coerce")
    bad = values.isna() & frame.notna() & (frame.astype(str).apply(lambda c: c.str.strip()) != "")
    if bad.to_numpy().any():
        i, k = (int(v[0]) for v in np.nonzero(bad.to_numpy()))
        raise LogFormatError(f"{path}: data row {i + 1}, column {k + 1} holds {frame.iat[i, k]!r}, not a number")
    return values.to_numpy(dtype=np.float64)
