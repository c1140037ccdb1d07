"""Kinematic sensor faults outside ``diagnose``'s vocabulary, added to a clean session of the
project's simulator in their physical form (issue #31, item 1; the shapes a real robot has that no
cause names). Written to judge the diagnosis, which never sees them:

- ``worn_track``: a worn spot on a pot's resistive track, a dip (or bump) in its transfer curve a
  twentieth of the visited range wide, somewhere in the middle of that range (peak size);
- ``runout``: a pot read through a gear with runout: a sine of its reading, 3-6 periods over the
  visited range (amplitude);
- ``warm_up``: a pot's bias drifting as its electronics warm up, ``a (1 - exp(-t / 8 s))`` (a);
- ``crosstalk``: a pot picking up another pot's signal (a shared ground return): ``k`` times that
  pot's reading about its mean (RMS);
- ``wobble``: a marker on a compliant stalk, displaced by its own acceleration, ``-a / ω²`` with a
  6-Hz stalk (RMS distance per axis).

Sizes are U(4, 10) × the channel's noise; the session is the naming bench's (a 30-s finger log: 7
pots, tendons among them, 5 markers; 5 mV pot and 2 mm marker noise).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from diegocal.sim.kinematics import KinematicsOptions

SHAPES = ("worn_track", "runout", "warm_up", "crosstalk", "wobble")
SESSION = KinematicsOptions(duration=30.0)  # the simulator's noise, as the naming bench's
POT_NOISE, MARKER_NOISE = SESSION.pot_noise, SESSION.marker_noise
STALK_HZ = 6.0
WARM_UP_S = 8.0


def clean_session(seed: int):
    """A clean finger log and its robot, the noise-free pot readings (T, P) and markers (T, M, 3)."""
    from diegocal.robot import load_robot, resolve_robot_dir
    from diegocal.robot.observe import pot_transmission
    from diegocal.sim.kinematics import marker_positions, offset_robot, simulate_kinematics
    from diegocal.stac.calibration import Calibration

    robot = load_robot(resolve_robot_dir("finger", None))
    log = simulate_kinematics(robot, SESSION, np.random.default_rng(seed))
    truth = Calibration.from_dict(log.truth.params)
    q = log.truth.signals["q"].data
    fast = offset_robot(robot, {})
    pots = truth.gain * pot_transmission(fast, q) + truth.bias
    return log, robot, pots, marker_positions(fast, q, truth)


def add_shape(shape: str, seed: int):
    """The clean log with ``shape`` added to one channel: (log, robot, channel, ratio)."""
    log, robot, pots, markers = clean_session(seed)
    rng = np.random.default_rng([seed, 2])
    ratio = rng.uniform(4.0, 10.0)
    t = log.time
    p = log.streams["pots"].data.copy()
    names = log.streams["pots"].names
    i = int(rng.integers(len(names)))
    s = pots[:, i]
    lo, hi = np.quantile(s, [0.02, 0.98])
    if shape == "worn_track":
        c = rng.uniform(lo + 0.2 * (hi - lo), hi - 0.2 * (hi - lo))
        w = 0.05 * (hi - lo)
        p[:, i] += rng.choice((-1, 1)) * ratio * POT_NOISE * np.exp(-0.5 * ((s - c) / (0.5 * w)) ** 2)
    elif shape == "runout":
        periods = rng.uniform(3.0, 6.0)
        p[:, i] += ratio * POT_NOISE * np.sin(2 * np.pi * periods * (s - lo) / (hi - lo) + rng.uniform(0, 2 * np.pi))
    elif shape == "warm_up":
        p[:, i] += rng.choice((-1, 1)) * ratio * POT_NOISE * (1.0 - np.exp(-(t - t[0]) / WARM_UP_S))
    elif shape == "crosstalk":
        j = (i + 1 + int(rng.integers(len(names) - 1))) % len(names)
        other = pots[:, j] - pots[:, j].mean()
        p[:, i] += ratio * POT_NOISE * other / np.sqrt(np.mean(other**2))
    elif shape == "wobble":
        x = log.streams["markers"].data.copy()
        m = int(rng.integers(x.shape[1]))
        acc = np.gradient(np.gradient(markers[:, m], t, axis=0), t, axis=0)
        d = -acc / (2 * np.pi * STALK_HZ) ** 2
        x[:, m] += d * ratio * MARKER_NOISE / np.sqrt(np.mean(np.sum(d * d, axis=1)) / 3)
        streams = {**log.streams, "markers": replace(log.streams["markers"], data=x)}
        return replace(log, streams=streams), robot, log.streams["markers"].names[m], ratio
    streams = {**log.streams, "pots": replace(log.streams["pots"], data=p)}
    return replace(log, streams=streams), robot, names[i], ratio
