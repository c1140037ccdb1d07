"""A log's vital signs: what `diegocal inspect` prints and the report's log page shows."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from diegocal.io.log import Log


@dataclass(frozen=True)
class StreamSummary:
    """One stream: channel count, names, and the fraction of NaN samples per channel."""

    name: str
    names: tuple[str, ...]
    shape: tuple[int, ...]
    nan_fraction: np.ndarray  # (K,)
    low: np.ndarray  # (K,) finite minimum per channel
    high: np.ndarray  # (K,) finite maximum per channel


@dataclass(frozen=True)
class LogSummary:
    n_samples: int
    duration: float  # s
    rate_hz: float  # median sample rate, Hz
    nominal_rate_hz: float | None
    robot: str | None
    streams: tuple[StreamSummary, ...]
    has_truth: bool


def describe_log(log: Log) -> LogSummary:
    """Summarise a log: duration, rate (median of 1/Δt), per-stream NaN fraction and range."""
    dt = np.diff(log.time)
    rate = float(1.0 / np.median(dt)) if dt.size else float("nan")
    streams = []
    for name, s in log.streams.items():
        data = s.data.reshape(s.data.shape[0], len(s.names), -1)
        nan = np.isnan(data).any(axis=2).mean(axis=0) if data.shape[0] else np.zeros(len(s.names))
        with np.errstate(all="ignore"):
            finite = np.where(np.isfinite(data), data, np.nan)
            low = np.nanmin(finite, axis=(0, 2)) if np.isfinite(finite).any() else np.full(len(s.names), np.nan)
            high = np.nanmax(finite, axis=(0, 2)) if np.isfinite(finite).any() else np.full(len(s.names), np.nan)
        streams.append(StreamSummary(name, s.names, s.data.shape, nan, low, high))
    return LogSummary(log.n_samples, log.duration, rate, log.rate_hz, log.robot, tuple(streams), log.truth is not None)
