"""The diegocal log: time-stamped streams of named channels (DESIGN.md, "Log format", version 1).

A :class:`Log` is an in-memory, validated view of one recording. Streams are plain float64
arrays, samples first: ``(T, K)`` for every stream but ``markers``, which is ``(T, K, 3)``
(metres, NaN where occluded). Simulated logs also carry a :class:`Truth`, which only the
simulator writes and only tests and reports read; fitting code never touches it.
"""

from __future__ import annotations

import difflib
from dataclasses import dataclass, field, replace

import numpy as np

from diegocal.errors import LogFormatError, MissingStreamError, UnknownNameError

FORMAT = "diegocal-log"
VERSION = 1

#: Streams whose samples may be NaN (an occluded marker). Every other stream forbids NaN.
NAN_ALLOWED = frozenset({"markers"})

#: Streams stored as (T, K, 3) rather than (T, K).
VECTOR_STREAMS = frozenset({"markers"})

#: Streams whose channels are the robot's joints (URDF names).
JOINT_STREAMS = ("q", "qd", "qdd", "tau")

#: The streams diegocal reads or writes (DESIGN.md's table, plus predict's outputs). A log may
#: carry others (extend freely), but one whose name is a near miss of these is a typo.
KNOWN_STREAMS = ("pots", "markers", *JOINT_STREAMS, "pressure", "valve", "tau_std", "tau_measured")


def close_match(name: str, choices, cutoff: float = 0.6) -> str | None:
    """The choice ``name`` most likely misspells (difflib), or None."""
    match = difflib.get_close_matches(name, [c for c in choices if c != name], n=1, cutoff=cutoff)
    return match[0] if match else None


def unknown_streams(names, where: str) -> list[str]:
    """Stream names that are not diegocal's: raises LogFormatError for a near miss of a known
    stream (``tua`` for ``tau``: a typo must not silently become a stream of its own), returns
    the others (the caller says it keeps them)."""
    out = []
    for name in names:
        if name in KNOWN_STREAMS:
            continue
        match = close_match(name, KNOWN_STREAMS, cutoff=0.65)
        if match is not None:
            raise LogFormatError(f"{where}: stream {name!r} is not a diegocal stream — did you mean {match!r}?")
        out.append(name)
    return out


@dataclass(frozen=True)
class Stream:
    """Named channels sampled on the log's time base.

    Attributes
    ----------
    names : tuple of str, length K
    data : ndarray of shape (T, K), or (T, K, 3) for markers; float64, unit per stream (DESIGN.md)
    label : the stream's name in its log ("tau"), for messages ("" where not known)
    """

    names: tuple[str, ...]
    data: np.ndarray
    label: str = field(default="", compare=False)

    def column(self, name: str) -> np.ndarray:
        """Samples of one channel: shape (T,) or (T, 3)."""
        return self.data[:, self.index(name)]

    def index(self, name: str) -> int:
        try:
            return self.names.index(name)
        except ValueError:
            where = f"the log's {self.label!r} stream" if self.label else "stream"
            raise UnknownNameError(f"no channel {name!r} in {where} (has {_preview(self.names)})") from None

    def select(self, names) -> Stream:
        """A stream with only the named channels, in the given order. Every channel in the stream's
        own order: the same samples, not a copy (a long log's are hundreds of MB), read-only."""
        idx = [self.index(n) for n in names]
        if idx == list(range(len(self.names))):
            data = self.data.view()
            data.flags.writeable = False
            return Stream(tuple(names), data, self.label)
        return Stream(tuple(names), self.data[:, idx], self.label)


@dataclass(frozen=True)
class Truth:
    """Ground truth recorded by the simulator (``/truth``); never read by fitting code.

    Attributes
    ----------
    params : dict
        True parameters, in the schema the fitting command writes (e.g. calib.yaml's).
    effects : list of dict
        Injected effects: ``{cause, channel, region, values}``.
    signals : dict of str -> Stream
        True hidden signals such as ``q``.
    """

    params: dict = field(default_factory=dict)
    effects: list = field(default_factory=list)
    signals: dict = field(default_factory=dict)


@dataclass(frozen=True)
class Log:
    """One recording: a strictly increasing time base and named streams.

    Attributes
    ----------
    time : ndarray of shape (T,), seconds
    streams : dict of str -> Stream
    robot : str or None, the robot's name (looked up in the bundled ``robots/``)
    rate_hz : float or None, nominal sample rate
    truth : Truth or None, simulator ground truth
    nan_ok : bool, accept NaN in every stream (``diegocal inspect`` shows where they are; every
        fitting command reads logs without it and refuses NaN outside markers)
    source : dict or None, what made a derived log (``diegocal predict``: command, model, log,
        created); None for a recording or a simulation. Kept in HDF5 files only.
    """

    time: np.ndarray
    streams: dict
    robot: str | None = None
    rate_hz: float | None = None
    truth: Truth | None = None
    nan_ok: bool = field(default=False, compare=False, repr=False)
    source: dict | None = field(default=None, compare=False, repr=False)

    def __post_init__(self):
        check_log(self, allow_nan=self.nan_ok)

    @property
    def n_samples(self) -> int:
        return int(self.time.shape[0])

    @property
    def duration(self) -> float:
        return float(self.time[-1] - self.time[0]) if self.n_samples > 1 else 0.0

    def has(self, name: str) -> bool:
        return name in self.streams

    def stream(self, name: str, needed_by: str | None = None) -> Stream:
        """The named stream, or a one-line error saying which command needed it."""
        if name not in self.streams:
            who = f" (needed by {needed_by})" if needed_by else ""
            have = ", ".join(sorted(self.streams)) or "none"
            match = close_match(name, self.streams)
            hint = f" — did you mean {match!r}?" if match else ""
            if name in ("qd", "qdd") and "q" in self.streams:  # a bag's joint states: positions, velocities
                hint = f"; `diegocal import` derives it from q (`derive: [{name}]` in the import map)"
            raise MissingStreamError(f"log has no '{name}' stream{who}; it has: {have}{hint}")
        found = self.streams[name]
        return found if found.label else replace(found, label=name)

    def with_streams(self, **streams: Stream) -> Log:
        """A copy with streams added or replaced."""
        return replace(self, streams={**self.streams, **streams})

    def without_truth(self) -> Log:
        return replace(self, truth=None)

    def slice(self, start: int, stop: int) -> Log:
        """Samples ``start:stop`` of every stream (truth signals included)."""
        return self.take(slice(start, stop))

    def take(self, idx) -> Log:
        """Samples ``idx`` (a slice or an index array) of every stream (truth signals included)."""
        cut = {k: Stream(s.names, s.data[idx]) for k, s in self.streams.items()}
        truth = self.truth
        if truth is not None:
            sig = {k: Stream(s.names, s.data[idx]) for k, s in truth.signals.items()}
            truth = replace(truth, signals=sig)
        return replace(self, time=self.time[idx], streams=cut, truth=truth)


def split_index(log: Log, at: float, unit: str) -> int:
    """The first sample of the second part when ``log`` is cut at ``at``: a fraction of its samples
    (``unit='fraction'``, 0 < at < 1) or seconds from its start (``unit='seconds'``). Raises
    ValueError (the caller's usage error) when either part would have fewer than 2 samples."""
    T = log.n_samples
    if unit == "fraction":
        if not 0.0 < at < 1.0:
            raise ValueError(f"a fraction must lie strictly between 0 and 1, got {at:g}")
        k = int(round(at * T))
    elif unit == "seconds":
        if not 0.0 < at < log.duration:
            raise ValueError(f"{at:g} s is outside the log (0 to {log.duration:.6g} s)")
        k = int(np.searchsorted(log.time, log.time[0] + at, side="left"))
    else:
        raise ValueError(f"unknown unit {unit!r}")
    if k < 2 or T - k < 2:
        raise ValueError(f"the cut leaves {k} and {T - k} samples; each part needs at least 2")
    return k


def split_log(log: Log, at: float, unit: str = "fraction") -> tuple[Log, Log]:
    """Two contiguous parts of a log (train, held out), cut at :func:`split_index`; each keeps the
    robot, rate and the simulator's truth signals of its samples."""
    k = split_index(log, at, unit)
    return log.slice(0, k), log.slice(k, log.n_samples)


def check_stream(name: str, stream: Stream, n_samples: int, allow_nan: bool = False) -> None:
    """Validate one stream's shape, names and values against the log's length (NaN only in
    markers, unless ``allow_nan``)."""
    names = stream.names
    if not all(isinstance(n, str) and n for n in names):
        raise LogFormatError(f"stream '{name}': channel names must be non-empty strings")
    if len(set(names)) != len(names):
        dup = sorted({n for n in names if names.count(n) > 1})
        raise LogFormatError(f"stream '{name}': duplicate channel names {dup}")
    data = stream.data
    want = (n_samples, len(names), 3) if name in VECTOR_STREAMS else (n_samples, len(names))
    if data.shape != want:
        raise LogFormatError(f"stream '{name}': expected data of shape {want}, got {data.shape}")
    if data.dtype != np.float64:
        raise LogFormatError(f"stream '{name}': expected float64 data, got {data.dtype}")
    if name not in NAN_ALLOWED and not allow_nan and data.size and not np.isfinite(data).all():
        bad = np.argwhere(~np.isfinite(data.reshape(n_samples, -1)))
        t, k = int(bad[0][0]), int(bad[0][1])
        raise LogFormatError(
            f"stream '{name}': NaN or infinite value at sample {t}, channel {names[k]!r} "
            f"({len(bad)} in all); only markers may be NaN"
        )


def check_log(log: Log, allow_nan: bool = False) -> None:
    """Validate a whole log; raises :class:`LogFormatError` with one clear line."""
    time = log.time
    if not isinstance(time, np.ndarray) or time.ndim != 1:
        raise LogFormatError(f"time: expected shape (T,), got {np.shape(time)}")
    if time.shape[0] == 0:
        raise LogFormatError("time: the log has no samples")
    if not np.isfinite(time).all():
        raise LogFormatError(f"time: NaN or infinite value at sample {int(np.argmin(np.isfinite(time)))}")
    steps = np.diff(time)
    if (steps <= 0).any():
        i = int(np.argmax(steps <= 0))
        raise LogFormatError(
            f"time: not strictly increasing at sample {i + 1} ({time[i]:.6g} s then {time[i + 1]:.6g} s)"
        )
    for name, stream in log.streams.items():
        if not isinstance(stream, Stream):
            raise LogFormatError(f"stream '{name}': expected a Stream, got {type(stream).__name__}")
        check_stream(name, stream, time.shape[0], allow_nan)


def make_stream(names, data) -> Stream:
    """Coerce names to a tuple of str and data to float64."""
    return Stream(tuple(str(n) for n in names), np.asarray(data, dtype=np.float64))


def _preview(names, n: int = 6) -> str:
    shown = ", ".join(names[:n])
    return shown + (", ..." if len(names) > n else "")
