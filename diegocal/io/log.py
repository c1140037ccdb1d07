"""The diegocal log: time-stamped streams of named channels (DESIGN.md, "Log format", version 1).

A :class:`Log` is an in-memory, validated view of one recording. Streams are plain float64
arrays, samples first: ``(T, K)`` for every stream but ``markers``, which is ``(T, K, 3)``
(metres, NaN where occluded). Simulated logs also carry a :class:`Truth`, which only the
simulator writes and only tests and reports read; fitting code never touches it.
"""

from __future__ import annotations

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


@dataclass(frozen=True)
class Stream:
    """Named channels sampled on the log's time base.

    Attributes
    ----------
    names : tuple of str, length K
    data : ndarray of shape (T, K), or (T, K, 3) for markers; float64, unit per stream (DESIGN.md)
    """

    names: tuple[str, ...]
    data: np.ndarray

    def column(self, name: str) -> np.ndarray:
        """Samples of one channel: shape (T,) or (T, 3)."""
        return self.data[:, self.index(name)]

    def index(self, name: str) -> int:
        try:
            return self.names.index(name)
        except ValueError:
            raise UnknownNameError(f"no channel {name!r} in stream (has {_preview(self.names)})") from None

    def select(self, names) -> Stream:
        """A stream with only the named channels, in the given order."""
        idx = [self.index(n) for n in names]
        return Stream(tuple(names), self.data[:, idx])


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
    """

    time: np.ndarray
    streams: dict
    robot: str | None = None
    rate_hz: float | None = None
    truth: Truth | None = None

    def __post_init__(self):
        check_log(self)

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
            raise MissingStreamError(f"log has no '{name}' stream{who}; it has: {have}")
        return self.streams[name]

    def with_streams(self, **streams: Stream) -> Log:
        """A copy with streams added or replaced."""
        return replace(self, streams={**self.streams, **streams})

    def without_truth(self) -> Log:
        return replace(self, truth=None)

    def slice(self, start: int, stop: int) -> Log:
        """Samples ``start:stop`` of every stream (truth signals included)."""
        cut = {k: Stream(s.names, s.data[start:stop]) for k, s in self.streams.items()}
        truth = self.truth
        if truth is not None:
            sig = {k: Stream(s.names, s.data[start:stop]) for k, s in truth.signals.items()}
            truth = replace(truth, signals=sig)
        return replace(self, time=self.time[start:stop], streams=cut, truth=truth)


def check_stream(name: str, stream: Stream, n_samples: int) -> None:
    """Validate one stream's shape, names and values against the log's length."""
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
    if name not in NAN_ALLOWED and data.size and not np.isfinite(data).all():
        bad = np.argwhere(~np.isfinite(data.reshape(n_samples, -1)))
        t, k = int(bad[0][0]), int(bad[0][1])
        raise LogFormatError(
            f"stream '{name}': NaN or infinite value at sample {t}, channel {names[k]!r} "
            f"({len(bad)} in all); only markers may be NaN"
        )


def check_log(log: Log) -> None:
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
        check_stream(name, stream, time.shape[0])


def make_stream(names, data) -> Stream:
    """Coerce names to a tuple of str and data to float64."""
    return Stream(tuple(str(n) for n in names), np.asarray(data, dtype=np.float64))


def _preview(names, n: int = 6) -> str:
    shown = ", ".join(names[:n])
    return shown + (", ..." if len(names) > n else "")
