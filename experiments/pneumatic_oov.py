"""Pneumatic faults outside ``diagnose``'s vocabulary, in their physical form, on sessions of the
independent thin-plate generator (:mod:`experiments.pneumatic_generator`; issue #31, item 1: the
shapes a real valve-chamber system has that no cause names). Written to judge the diagnosis,
which never sees them:

- ``span_error``: the pressure sensor's gain is off, ``P_r + k (p - P_r)``, |k - 1| sized so that
  the reading's RMS change is the ratio × the sensor's noise (a membrane or amplifier off its
  calibration; the vocabulary's offset is the sensor's zero);
- ``zero_drift``: the sensor's zero drifts linearly over the session as it warms, from 0 to
  ``a`` (RMS ratio × noise): an offset that is not constant;
- ``slow_sensor``: the reading lags the pressure through a first-order filter, time constant
  30-60 ms (a sensor at the end of a long thin tube), where the vocabulary's lag is at most a tick
  and its delay the valve's;
- ``valve_play``: the valve's spool has 0.15-0.35 V of play (the generator's ``valve_play``): it
  follows the command half the play behind and, on a reversal, holds until the command has come
  back the whole play; the opening lags the logged command.

The sensor faults change the noise-free reading (``/truth/signals/reading``) and keep the log's
own noise; the play is physics (the generator integrates the valve's command through it). Sizes:
ratio U(4, 10) for the two that scale; the session is the naming bench's (60 s, the generator's
defaults).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from experiments import pneumatic_generator as gen

SHAPES = ("span_error", "zero_drift", "slow_sensor", "valve_play")
SESSION = gen.GeneratorOptions(duration=60.0)
PLAY_V = (0.15, 0.35)
SLOW_S = (0.030, 0.060)


def slow_reading(reading: np.ndarray, time: np.ndarray, tau: float) -> np.ndarray:
    """``reading`` (T,) seen through a first-order filter of time constant ``tau`` (s), each sample
    held over the step before it, started at the first reading."""
    alpha = 1.0 - np.exp(-np.diff(time) / tau)
    out = reading.copy()
    for k in range(1, len(out)):
        out[k] = out[k - 1] + alpha[k - 1] * (reading[k] - out[k - 1])
    return out


def session(seed: int, duration: float | None = None) -> gen.GeneratorOptions:
    """The generator's options of the session :func:`add_shape` puts a sensor fault on."""
    return replace(SESSION, seed=seed, duration=duration or SESSION.duration)


def add_shape(shape: str, seed: int, chamber: str | None = None, duration: float | None = None, log=None):
    """A session of the generator with ``shape`` on one chamber (drawn unless given): (log, chamber,
    size), the size in the shape's unit (k - 1, kPa, s or V). ``log``: the session
    (:func:`session`) generated already, with others (``generate_many``), for a sensor fault."""
    rng = np.random.default_rng([seed, 0x00F])
    chambers = gen.load_chambers()
    chamber = chamber or chambers.names[int(rng.integers(len(chambers.names)))]
    ratio = rng.uniform(4.0, 10.0)
    sign = rng.choice((-1.0, 1.0))
    options = session(seed, duration)
    if shape == "valve_play":
        if log is not None:
            raise ValueError("valve play is physics: its session is generated with it")
        size = rng.uniform(*PLAY_V)
        log = gen.generate(replace(options, effects=(gen.Effect("valve_play", chamber, size),)))
        return log, chamber, size
    log = gen.generate(options) if log is None else log
    i = log.streams["pressure"].names.index(chamber)
    reading = log.truth.signals["reading"].data[:, i]
    noise = options.pressure_noise
    if shape == "span_error":
        room = chambers.room[i] / gen.KPA
        dev = reading - room
        size = sign * ratio * noise / np.sqrt(np.mean(dev**2))
        new = reading + size * dev
    elif shape == "zero_drift":
        t = (log.time - log.time[0]) / (log.time[-1] - log.time[0])
        size = sign * ratio * noise * np.sqrt(3.0)  # a ramp from 0 to a has RMS a / sqrt(3)
        new = reading + size * t
    elif shape == "slow_sensor":
        size = rng.uniform(*SLOW_S)
        new = slow_reading(reading, log.time, size)
    else:
        raise ValueError(f"unknown shape {shape!r}; one of {', '.join(SHAPES)}")
    p = log.streams["pressure"].data.copy()
    p[:, i] += new - reading
    streams = {**log.streams, "pressure": replace(log.streams["pressure"], data=p)}
    return replace(log, streams=streams), chamber, float(size)
