"""One valve-chamber system's samples taken from a log: u, p, v and vdot (thesis §4.5.3).

The volume coordinate ``v`` is the chamber's ``volume_sensor`` pot, read in its own unit
(§4.4: "there is no need to explicitly convert to units of cm³"); ``vdot`` is its forward
finite difference, so that the step from sample t to t+1 sees the volume change over that step.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from diegocal.errors import FitError, LogFormatError, UnknownNameError
from diegocal.io import Log
from diegocal.robot.sensors import ChamberSpec, SensorConfig

#: The valve's accepted command range, V (FESTO MPYE: 0-10 V; the thesis used 3-7 V, §4.5).
VALVE_RANGE = (0.0, 10.0)
#: A chamber whose pressure spans less than this fraction of P_c - P_r cannot be identified.
MIN_PRESSURE_SPAN = 0.02
MIN_SAMPLES = 50


@dataclass(frozen=True)
class ChamberData:
    """Samples of one valve-chamber system.

    Attributes
    ----------
    name : chamber name
    time : (T,) s;  u : (T,) V;  p : (T,) pressure unit;  v : (T,) volume-sensor unit
    vd : (T,) volume-sensor unit per second (forward difference; the last one repeated)
    supply, room : P_c and P_r in the pressure unit
    """

    name: str
    time: np.ndarray
    u: np.ndarray
    p: np.ndarray
    v: np.ndarray
    vd: np.ndarray
    supply: float
    room: float

    @property
    def h(self) -> np.ndarray:
        """Step lengths (T-1,), s."""
        return np.diff(self.time)

    @property
    def n_samples(self) -> int:
        return int(self.time.shape[0])

    @property
    def steps(self) -> np.ndarray:
        """(T-1,) bool: True where sample t+1 follows sample t without a gap in the recording
        (a step longer than 1.5 times the median is a gap between sessions)."""
        h = np.diff(self.time)
        return h <= 1.5 * np.median(h)

    def segment_starts(self) -> np.ndarray:
        """Indices where a gap-free stretch of the recording begins."""
        return np.concatenate([[0], np.flatnonzero(~self.steps) + 1])

    def u_lags(self, n: int) -> np.ndarray:
        """(T, n + 1) the commands u_t, u_{t-1}, ..., u_{t-n} (V); before the start of a gap-free
        stretch the stretch's first command is repeated (no command crosses a session gap)."""
        T = self.n_samples
        first = np.repeat(self.segment_starts(), np.diff(np.append(self.segment_starts(), T)))
        idx = np.maximum(np.arange(T)[:, None] - np.arange(n + 1)[None, :], first[:, None])
        return self.u[idx]


def chamber_spec(sensors: SensorConfig, name: str) -> ChamberSpec:
    for c in sensors.chambers:
        if c.name == name:
            return c
    names = sensors.chamber_names
    shown = ", ".join(names[:8]) + (", ..." if len(names) > 8 else "")
    raise UnknownNameError(
        f"chamber {name!r} is not in sensors.yaml (has {len(names)}: {shown or 'none'})"
    )


def forward_rate(time: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Forward finite difference of x (T,) over time (T,): (x[t+1] - x[t]) / h.

    The last sample of the log and of every gap-free stretch repeats the previous difference.
    """
    h = np.diff(time)
    d = np.diff(x) / h
    d = np.concatenate([d, d[-1:]])
    gap = np.flatnonzero(h > 1.5 * np.median(h))
    d[gap] = d[np.maximum(gap - 1, 0)]
    return d


def chamber_data(
    log: Log, sensors: SensorConfig, name: str, check_span: bool = True
) -> ChamberData:
    """Extract and validate one chamber's u, p, v, vdot from ``log`` (chamber from sensors.yaml).

    Raises UnknownNameError (chamber or channel unknown), MissingStreamError (no pressure,
    valve or pots stream), LogFormatError (voltage outside the valve's range) and FitError
    (too few samples; pressure that never moves, so the model is unidentifiable).
    """
    spec = chamber_spec(sensors, name)
    valve_range = tuple(spec.extra.get("valve_range", VALVE_RANGE))
    return extract(log, name, spec.volume_sensor, spec.supply, spec.room, valve_range, check_span)


def extract(
    log: Log,
    name: str,
    volume_sensor: str,
    supply: float,
    room: float,
    valve_range=VALVE_RANGE,
    check_span: bool = True,
) -> ChamberData:
    """:func:`chamber_data` with the chamber's facts given directly (as pneumatic.yaml has them)."""
    who = "pneumatic models"
    p = _channel(log, "pressure", name, who)
    u = _channel(log, "valve", name, who)
    v = _channel(log, "pots", volume_sensor, who)
    lo, hi = valve_range
    bad = (u < lo) | (u > hi)
    if bad.any():
        i = int(np.argmax(bad))
        raise LogFormatError(
            f"valve stream: chamber {name!r}: command {u[i]:.4g} V at sample {i} is outside the "
            f"valve's range {lo:g}-{hi:g} V ({int(bad.sum())} samples)"
        )
    if log.n_samples < MIN_SAMPLES:
        raise FitError(f"chamber {name!r}: {log.n_samples} samples; need at least {MIN_SAMPLES}")
    span = float(np.ptp(p))
    if check_span and span < MIN_PRESSURE_SPAN * (supply - room):
        raise FitError(
            f"chamber {name!r}: pressure spans only {span:.3g} (< {MIN_PRESSURE_SPAN:.0%} of "
            f"supply - room); the valve never moved it, so its model is unidentifiable"
        )
    return ChamberData(name, log.time, u, p, v, forward_rate(log.time, v), supply, room)


def _channel(log: Log, stream: str, channel: str, who: str) -> np.ndarray:
    s = log.stream(stream, needed_by=who)
    if channel not in s.names:
        raise UnknownNameError(f"log stream '{stream}' has no channel {channel!r}")
    return s.column(channel)
