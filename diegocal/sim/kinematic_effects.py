"""The kinematic simulator's effects: which effect goes where, with what size (:func:`plan_effects`),
and the ones it applies to the readings (a pot's dead band, swapped marker labels).

Effects are named by the registry's kinematic causes (:mod:`diegocal.causes`) and injected by
:func:`diegocal.sim.kinematics.simulate_kinematics`; what each SIZE means is
:data:`diegocal.causes.KINEMATIC_SIZE_UNITS`.
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass, field

import numpy as np

from diegocal.robot import Robot
from diegocal.sim.effects import EffectError, EffectRequest, check_channel, effect_record


def bias_scale(robot: Robot, s: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Units of s per rad of joint angle, per pot (P,): 1 for rotary pots and encoders; for
    linear pots and tendons the ratio of the transmission's spread to the joints' median one."""
    spread_q = float(np.median(np.std(q, axis=0))) or 1.0
    scale = np.ones(len(robot.sensors.pots))
    for i, p in enumerate(robot.sensors.pots):
        if p.kind in ("linear", "tendon"):
            scale[i] = (float(np.std(s[:, i])) or 1e-3) / spread_q
    return scale



@dataclass
class EffectPlan:
    """Resolved effects: what the generator does differently, and the /truth records."""

    records: list = field(default_factory=list)
    joint_offsets: dict = field(default_factory=dict)  # joint -> (3,) m, in the parent frame
    backlash: dict = field(default_factory=dict)  # pot index -> dead band width, units of s
    nonlinear: dict = field(default_factory=dict)  # pot index -> (s0, c2)
    shift: float = 0.0  # markers[t] observe q(t + shift / rate): samples, not always whole
    slips: dict = field(default_factory=dict)  # marker index -> (sample, (3,) m)
    outliers: list = field(default_factory=list)  # (marker index, start, length, (3,) m)
    swaps: list = field(default_factory=list)  # (marker index, partner index, start, length)


def _effect_rng(seed: int, request: EffectRequest) -> np.random.Generator:
    """One generator per effect, keyed by its text: adding an effect never changes the others."""
    return np.random.default_rng([seed, zlib.crc32(str(request).encode())])


def observed_joints(robot: Robot) -> list[str]:
    """Joints that move at least one marker or linear-pot anchor (in robot joint order)."""
    links = [m.link for m in robot.sensors.markers]
    links += [a.link for p in robot.sensors.pots if p.kind == "linear" for a in p.anchors]
    model, out = robot.model, set()
    for link in links:
        j = model.frames[robot.frame_id(link)].parentJoint
        while j > 0:
            out.add(model.names[j])
            j = model.parents[j]
    return [n for n in robot.joint_names if n in out]


def _default_channel(request: EffectRequest, robot: Robot, rng) -> str:
    """A seeded choice of channel when the request names none."""
    pots = robot.sensors.pots
    analog = [p.name for p in pots if p.kind != "encoder"] or [p.name for p in pots]
    choices = {
        "link_offset": observed_joints(robot),
        "sensor_nonlinearity": analog,
        "backlash": analog,
        "marker_slip": list(robot.sensors.marker_names),
        "time_offset": ["markers"],
        "marker_outliers": ["markers"] if robot.sensors.markers else [],
        "swapped_labels": list(robot.sensors.marker_names) if len(robot.sensors.markers) > 1 else [],
    }[request.name]
    if not choices:
        raise EffectError(f"effect '{request.name}': robot {robot.name!r} has nothing it can act on")
    return str(choices[int(rng.integers(len(choices)))])


def _runs(rng, n_samples: int, fraction: float, low: int, high: int) -> list[tuple[int, int]]:
    """Non-overlapping runs (start, length) of U{low..high} samples covering about ``fraction``
    of ``n_samples``, at uniformly random places."""
    runs, covered = [], np.zeros(n_samples, dtype=bool)
    target = int(round(fraction * n_samples))
    for _ in range(100 * max(target, 1)):  # bounded: stops when the target is covered
        if covered.sum() >= target:
            break
        length = int(rng.integers(low, high + 1))
        start = int(rng.integers(0, max(n_samples - length, 0) + 1))
        if not covered[start : start + length].any():
            covered[start : start + length] = True
            runs.append((start, length))
    return sorted(runs)


def _nearest_marker(x: np.ndarray, m: int, distance: float | None = None) -> int:
    """The marker whose true path (T, M, 3) stays closest to marker m's on average (``distance``
    given, m: the one whose mean distance is nearest it)."""
    d = np.linalg.norm(x - x[:, m : m + 1], axis=-1).mean(axis=0)
    if distance is not None:
        d = np.abs(d - distance)
    d[m] = np.inf
    return int(np.argmin(d))


def plan_effects(
    robot: Robot,
    options,  # diegocal.sim.kinematics.KinematicsOptions
    s: np.ndarray,
    q: np.ndarray,
    gain: np.ndarray,
    seed: int,
    x: np.ndarray | None = None,
) -> EffectPlan:
    """Draw every requested effect's true values (seeded per effect) and its /truth record.

    ``s`` (T, P) transmission quantities and ``q`` (T, n) joint angles of the effect-free run
    set the scale of pot effects; ``gain`` (P,) the true pot gains; ``x`` (T, M, 3) the clean
    marker paths choose a swapped label's partner.

    - ``link_offset:JOINT``: the joint's origin moves by 5-10 mm (random direction, or the
      options' ``directions[JOINT]``).
    - ``backlash:POT``: play operator of width 0.02-0.05 rad (equivalent) on s.
    - ``sensor_nonlinearity:POT``: ``c2 (s - s0)²`` added, peak 5-10 % of the half-range.
    - ``time_offset:markers``: markers[t] observe q(t + k/rate), |k| = 3..8 samples.
    - ``marker_slip:MARKER``: the marker moves 1-3 cm on its link at 30-70 % of the run.
    - ``marker_outliers[:MARKER]``: in 1-3 % of the samples of each marker (``markers``, the
      default) or of the one named, the reading is off by 3-15 cm in a random direction, for
      runs of 1-5 samples (ghosts, reflections, a neighbour's label for an instant).
    - ``swapped_labels:MARKER``: the marker and its nearest neighbour (on average over the run)
      exchange labels in 3-8 % of the samples, in runs of 0.2-1 s.

    A request's ``size`` replaces the drawn magnitude (:data:`SIZE_UNITS`); the direction, sign,
    time and runs are drawn as without it. A size that makes no sense for the channel (a transfer
    curve that would turn back, a dead band wider than the pot's range, a clock shift of half the
    run) raises :class:`EffectError`.
    """
    plan = EffectPlan()
    pots, markers = robot.sensors.pot_names, robot.sensors.marker_names
    scale = bias_scale(robot, s, q)
    T = options.n_samples
    for req in options.effects:
        rng = _effect_rng(seed, req)
        req = EffectRequest(req.name, req.channel or _default_channel(req, robot, rng), req.size)
        channel, size = req.channel, req.size
        if req.name == "link_offset":
            check_channel(req, robot.joint_names, "joint")
            d = rng.normal(size=3)
            if channel in options.directions:
                d = np.asarray(options.directions[channel], float)
            d *= (rng.uniform(0.005, 0.010) if size is None else size) / np.linalg.norm(d)
            plan.joint_offsets[channel] = d
            values = {"dxyz": d, "frame": "joint origin, in the parent joint frame"}
        elif req.name == "backlash":
            i = pots.index(check_channel(req, pots, "pot"))
            width = rng.uniform(0.02, 0.05) * scale[i] if size is None else size / abs(gain[i])
            span = float(np.ptp(s[:, i]))
            if size is not None and width >= span:
                raise EffectError(
                    f"effect '{req}': a dead band of {abs(gain[i]) * width:g} V is wider than the pot's "
                    f"range in this run ({abs(gain[i]) * span:.3g} V): the reading would never move"
                )
            plan.backlash[i] = width
            values = {"width": width, "width_reading": abs(gain[i]) * width}
        elif req.name == "sensor_nonlinearity":
            i = pots.index(check_channel(req, pots, "pot"))
            lo, hi = float(s[:, i].min()), float(s[:, i].max())
            s0, half = 0.5 * (lo + hi), max(0.5 * (hi - lo), 1e-9)
            peak = rng.uniform(0.05, 0.10) * abs(gain[i]) * half if size is None else size
            peak *= rng.choice([-1.0, 1.0])
            if abs(peak) >= 0.5 * abs(gain[i]) * half:  # slope g + 2 c2 (s - s0) keeps its sign
                raise EffectError(
                    f"effect '{req}': a departure of {abs(peak):g} V would make the transfer curve turn "
                    f"back; it must be below half the pot's half-range, {0.5 * abs(gain[i]) * half:.3g} V"
                )
            plan.nonlinear[i] = (s0, peak / half**2)
            values = {"form": "reading += c2 * (s - s0)**2", "s0": s0, "c2": peak / half**2, "peak": peak}
        elif req.name == "time_offset":
            check_channel(req, ["markers"], "clock (use time_offset:markers)")
            k = int(rng.integers(3, 9)) if size is None else size * options.rate_hz  # samples
            k *= int(rng.choice([-1, 1]))
            if size is not None and abs(k) >= T / 2:
                raise EffectError(
                    f"effect '{req}': a clock shift of {abs(k) / options.rate_hz:g} s is half the run or more"
                )
            plan.shift = k
            values = {"samples": k, "seconds": k / options.rate_hz, "convention": "markers[t] observe q(t + seconds)"}
        elif req.name == "marker_outliers":
            check_channel(req, ["markers", *markers], "marker (or 'markers' for all)")
            which = range(len(markers)) if channel == "markers" else [markers.index(channel)]
            fraction = rng.uniform(0.01, 0.03)
            for m in which:
                for start, length in _runs(rng, T, fraction, 1, 5):
                    d = rng.normal(size=3)
                    dist = rng.uniform(0.03, 0.15) if size is None else size
                    plan.outliers.append((m, start, length, d * dist / np.linalg.norm(d)))
            samples = sum(o[2] for o in plan.outliers)
            distance = [0.03, 0.15] if size is None else [size, size]
            values = {"fraction": fraction, "samples": samples, "distance": distance, "run_samples": [1, 5]}
        elif req.name == "swapped_labels":
            m = markers.index(check_channel(req, markers, "marker"))
            if len(markers) < 2 or x is None:
                raise EffectError(f"effect '{req}': needs a second marker to swap labels with")
            k = _nearest_marker(x, m, size)
            fraction = rng.uniform(0.03, 0.08)
            lo, hi = max(1, round(0.2 * options.rate_hz)), max(1, round(1.0 * options.rate_hz))
            runs = _runs(rng, T, fraction, lo, hi)
            plan.swaps += [(m, k, start, length) for start, length in runs]
            values = {
                "partner": markers[k],
                "distance": float(np.nanmean(np.linalg.norm(x[:, k] - x[:, m], axis=-1))),
                "fraction": fraction,
                "runs": len(runs),
                "samples": sum(r[1] for r in runs),
            }
        else:  # marker_slip
            m = markers.index(check_channel(req, markers, "marker"))
            t_slip = int(rng.uniform(0.3, 0.7) * T)
            d = rng.normal(size=3)
            d *= (rng.uniform(0.01, 0.03) if size is None else size) / np.linalg.norm(d)
            plan.slips[m] = (t_slip, d)
            t0 = t_slip / options.rate_hz
            values = {"sample": t_slip, "time": t0, "dxyz": d}
            # open: the marker stays moved after the log ends (DESIGN.md's regions end where the
            # effect does, not where the data do)
            plan.records.append(
                effect_record(req.name, channel, values, region={"variable": "time", "low": t0, "high": float("inf")})
            )
            continue
        plan.records.append(effect_record(req.name, channel, values))
    return plan


def backlash(s: np.ndarray, width: float) -> np.ndarray:
    """Play operator: the output (T,) follows ``s`` (T,) only once it leaves a dead band.

    Moving up, the reading lags by width/2; moving down, it leads by width/2 — a
    direction-dependent dead band (DESIGN.md ``backlash``). Starts centred on s[0].
    """
    out = np.empty_like(s)
    y, h = float(s[0]), 0.5 * width
    for t, v in enumerate(s.tolist()):
        y = min(max(y, v - h), v + h)
        out[t] = y
    return out


def record_displacement(plan: EffectPlan, shifted: np.ndarray, unshifted: np.ndarray) -> None:
    """Add to the clock shift's /truth record how far it moves the markers: the RMS over markers
    and samples of the distance between where they are read and where they are at the pots' time."""
    dist = np.linalg.norm(shifted - unshifted, axis=-1)
    for rec in plan.records:
        if rec["cause"] == "time_offset":
            rec["values"]["displacement_rms"] = float(np.sqrt(np.mean(dist**2)))


def corrupt_labels(x: np.ndarray, plan: EffectPlan) -> tuple[np.ndarray, np.ndarray]:
    """Markers (T, M, 3) with the plan's label swaps and outliers applied, and the mask (T, M)
    of readings that are not their own marker's (swaps first, then outliers on top)."""
    x = x.copy()
    bad = np.zeros(x.shape[:2], dtype=bool)
    for m, k, start, length in plan.swaps:
        sl = slice(start, start + length)
        x[sl, m], x[sl, k] = x[sl, k].copy(), x[sl, m].copy()
        bad[sl, m] = bad[sl, k] = True
    for m, start, length, d in plan.outliers:
        x[start : start + length, m] += d
        bad[start : start + length, m] = True
    return x, bad
