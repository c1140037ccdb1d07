"""The kinematic behaviour of the causes (:mod:`diegocal.causes`): how each extra term changes the
observation model of thesis eq. (2.11-2.20).

The baseline STAC model (thesis §2.3) predicts a pot reading ``p = gain · s(q) + bias`` and a
marker ``x = R (base_T_link(q) d) + T0``. Each extra term changes one part of it; this module is
the one place that says how, and both ``diagnose`` and ``predict`` use it:

- ``sensor_nonlinearity:POT`` (c2, c3, V): ``p = ŷ + c2 u² + c3 u³`` with ŷ = gain s + bias
  normalised ``u = (ŷ − center) / half`` (center and half range of the training readings in
  ``extra``): the pot's transfer curve is not linear.
- ``backlash:POT`` (half_width, V; ``extra.width`` W, V): ``p = ŷ − half_width · dir_t`` with
  ŷ = gain s + bias and dir_t = (ŷ − play(ŷ, W)) / (W / 2) in [−1, 1] (:func:`direction`), ŷ
  smoothed first (:data:`DIRECTION_SMOOTH`): the reading lags the joint by a dead band (the play
  operator when half_width = W / 2).
- ``link_offset:JOINT`` (dx, dy, dz, m): the joint's origin is translated in its parent joint's
  frame (the URDF's ``<origin xyz>`` is off).
- ``joint_geometry:JOINT`` (dx, dy, dz, m; rx, ry, rz, rad): the joint's placement is composed
  with ``SE3(exp(r), d)`` in its own nominal frame (origin and axis off; fitted from static poses
  by :mod:`diegocal.stac.geometry`, a companion of the baseline rather than a finding).
- ``time_offset:markers`` (seconds, s): the mocap clock is shifted: ``markers[t]`` observe
  ``q(t + seconds)``.
- ``marker_slip:MARKER`` (dx, dy, dz, m, region ``time`` from t0): from t0 on the marker sits at
  ``d + (dx, dy, dz)`` on its link.
- ``marker_outliers:MARKER`` (``extra.frames``: readings that are not the marker's) and
  ``swapped_labels:MARKER`` (``extra.partner``, ``extra.frames``): labelling faults of the mocap.

Rather than re-deriving STAC with each term, :func:`apply_terms` maps the log and the robot into
the baseline model's terms: pot readings with the transfer-curve terms removed (``p − f(p)``),
markers moved to the pots' clock, link offsets written into the Pinocchio model, a slipped marker
split into two markers (before, ``NAME~slip`` after t0), faulty readings removed or swapped back.
The baseline STAC machinery then fits and predicts unchanged; :func:`to_log_markers` maps its
marker prediction back to the log's markers and clock.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.signal import savgol_filter

from diegocal.causes import CAUSES as CAUSE_REGISTRY
from diegocal.causes import causes_of
from diegocal.io import Log, make_stream
from diegocal.robot import MarkerSpec, Robot
from diegocal.robot.model import perturb_joint_placements, shift_joint_origins
from diegocal.terms import Term

#: The kinematic causes this module implements (the registry's kinematic terms and faults).
CAUSES = causes_of("kinematics", "term", "fault")
#: Pot causes: they change a pot's reading (the others the markers).
POT_CAUSES = tuple(c for c in CAUSES if CAUSE_REGISTRY[c].channel == "pot")
#: Suffix of the second marker a slipped marker is split into.
SLIP = "~slip"
#: Width of the dead band (in pot noise σ) that tells a pot's direction of motion: the noise
#: rarely drags it, a real motion does.
BAND_SIGMAS = 6.0
#: Samples of the centred quadratic (Savitzky-Golay) smoother a dead band's direction is read
#: through. The model's reading at a tracked q carries the reading's own noise where the pot alone
#: fixes its joint (a wrist whose markers lie near its axis), and that noise, dragging the band
#: near each reversal, entered the direction column and the residual alike: half widths 20-30 %
#: short, 2.6-3.7 SE (UR5 wrists, the true band given). A quadratic keeps a smooth reversal's shape
#: and time.
DIRECTION_SMOOTH = 11


# ----------------------------------------------------------------------------- pot terms
def direction(p: np.ndarray, width: float) -> np.ndarray:
    """Where a reading (T,) sits in a dead band of ``width`` that it drags along (the play operator,
    Krasnosel'skii-Pokrovskii): (p − play(p)) / (width / 2) in [−1, 1], +1 after moving up by
    more than ``width``, −1 after moving down, held while the reading stands still; 0 at the
    start. Reading noise moves it by about noise / (width / 2)."""
    p = np.asarray(p, float)
    h = 0.5 * width
    out = np.empty_like(p)
    y = float(p[0])
    for t, v in enumerate(p.tolist()):
        y = min(max(y, v - h), v + h)
        out[t] = v - y
    return out / h


def pot_columns(term: Term, p: np.ndarray, model: np.ndarray | None = None) -> np.ndarray:
    """∂p̂/∂θ (T, k) of a pot term (module docstring), a function of the model's reading ``model``
    (T,) = gain s(q) + bias at a tracked q when given, else of the reading p (T,) itself (a first
    guess: a dead band then lags, a curve is bent by itself; :func:`apply_terms`)."""
    e = term.extra
    x = np.asarray(p if model is None else model, float)
    if term.cause == "sensor_nonlinearity":
        u = (x - e["center"]) / e["half"]
        return np.stack([u * u, u * u * u], axis=1)
    if term.cause == "backlash":
        return -direction(smoothed(x), e["width"])[:, None]
    raise ValueError(f"{term.cause} is not a pot term")


def smoothed(x: np.ndarray) -> np.ndarray:
    """A reading (T,) through the :data:`DIRECTION_SMOOTH`-sample centred quadratic smoother (as it
    is where it is shorter, or not finite)."""
    if x.size < DIRECTION_SMOOTH or not np.isfinite(x).all():
        return x
    return savgol_filter(x, DIRECTION_SMOOTH, 2)


def pot_extra(cause: str, p: np.ndarray, sigma: float) -> dict:
    """The fixed constants of a pot term from its training readings p (T,) and noise σ (V)."""
    if cause == "sensor_nonlinearity":
        lo, hi = float(np.min(p)), float(np.max(p))
        return {"center": 0.5 * (lo + hi), "half": max(0.5 * (hi - lo), 1e-9)}
    return {"width": float(BAND_SIGMAS * sigma)}


# ----------------------------------------------------------------------------- geometry
def offset_robot(robot: Robot, offsets: dict, extra_markers=(), geometry: dict | None = None) -> Robot:
    """A copy of ``robot`` with joint origins translated (joint -> (3,) m, in the parent joint's
    frame), joint placements perturbed (``geometry``: joint -> (6,), ``joint_geometry``) and
    ``extra_markers`` (MarkerSpec) appended to its sensors; its locked and continuous joints and
    its source kept (:meth:`Robot.with_model`: an extended model must not clip a continuous joint
    to ±π)."""
    model = perturb_joint_placements(shift_joint_origins(robot.model, offsets), geometry or {})
    sensors = robot.sensors
    if extra_markers:
        sensors = replace(sensors, markers=tuple(sensors.markers) + tuple(extra_markers))
    return robot.with_model(model, sensors)


def shift_clock(x: np.ndarray, time: np.ndarray, seconds: float) -> np.ndarray:
    """Readings (T, ...) resampled at ``time − seconds`` by linear interpolation (NaN where a
    neighbour is NaN or outside the log): markers[t] observing q(t + s) become markers observing q(t)."""
    if seconds == 0.0:
        return x
    t = np.asarray(time, float) - seconds
    i = np.clip(np.searchsorted(time, t) - 1, 0, time.size - 2)
    w = (t - time[i]) / (time[i + 1] - time[i])
    shape = (-1,) + (1,) * (x.ndim - 1)
    out = x[i] * (1.0 - w).reshape(shape) + x[i + 1] * w.reshape(shape)
    out[(t < time[0]) | (t > time[-1])] = np.nan
    return out


# ----------------------------------------------------------------------------- the mapping
@dataclass(frozen=True)
class Applied:
    """A log and robot mapped into the baseline STAC model's terms (module docstring).

    log : pots with transfer-curve terms removed, markers on the pots' clock, faults removed,
        slipped markers split (``NAME~slip`` from their slip sample on)
    robot : joint origins moved by the link offsets; the slipped markers' second markers added
    slips : second marker name -> (marker name, first sample)
    shift : the mocap clock offset, s
    time : (T,) the log's time, s
    marker_names : the log's own marker names
    """

    log: Log
    robot: Robot
    slips: dict
    shift: float
    time: np.ndarray
    marker_names: tuple


def slip_sample(term: Term, time: np.ndarray) -> int:
    return int(np.searchsorted(time, term.region.low - 1e-9))


def _shared(x: np.ndarray) -> np.ndarray:
    """A read-only float64 view of ``x``: a mapped log shares the readings no term changes (a copy
    is made where one does), and a write through it raises instead of changing the log's."""
    out = np.asarray(x, float).view()
    out.flags.writeable = False
    return out


def relabelled(markers: np.ndarray, names, terms) -> np.ndarray:
    """``markers`` (T, M, 3) with the labels of ``swapped_labels`` terms swapped back in their frames
    (a copy; without such a term a read-only view, :func:`_shared`)."""
    x = _shared(markers)
    names = list(names)
    for t in terms:
        if t.cause == "swapped_labels" and t.channel in names and t.extra["partner"] in names:
            x = np.array(x, float) if not x.flags.writeable else x
            a, b = names.index(t.channel), names.index(t.extra["partner"])
            f = np.asarray(t.extra.get("frames", ()), int)
            x[f, a], x[f, b] = x[f, b].copy(), x[f, a].copy()
    return x


def apply_terms(terms, log: Log, robot: Robot, model_pots: np.ndarray | None = None) -> Applied:
    """Map ``log`` and ``robot`` into the baseline model's terms (module docstring).

    ``model_pots`` (T, P) the baseline part gain s(q) + bias of each pot at a tracked q (a backlash
    acts on it); None: the readings themselves (a first pass: the dead band then lags)."""
    terms = tuple(terms)
    time = np.asarray(log.time, float)
    streams = {}
    if log.has("pots"):
        st = log.stream("pots")
        raw = st.data
        p = _shared(raw)  # copied only where a term maps it (issue #33: a fit's log shares the rest)
        for t in terms:
            if t.cause in POT_CAUSES and t.channel in st.names:
                j = st.names.index(t.channel)
                model = None if model_pots is None else model_pots[:, j]
                p = np.array(p, float) if not p.flags.writeable else p
                p[:, j] -= pot_columns(t, raw[:, j], model) @ t.values
        streams["pots"] = make_stream(st.names, p)
    names, slips, shift = (), {}, 0.0
    offsets, extra, geometry = {}, [], {}
    for t in terms:
        if t.cause == "link_offset":
            offsets[t.channel] = offsets.get(t.channel, 0.0) + t.values
        elif t.cause == "time_offset":
            shift += float(t.values[0])
        elif t.cause == "joint_geometry":
            geometry[t.channel] = t.values
    if log.has("markers"):
        st = log.stream("markers")
        names = tuple(st.names)
        specs = {m.name: m for m in robot.sensors.markers}
        x = relabelled(st.data, names, terms)  # labelling faults first: they are facts about the raw stream
        for t in terms:
            if t.cause == "marker_outliers":
                x = np.array(x, float) if not x.flags.writeable else x
                for m, f in (t.extra.get("frames") or {}).items():
                    if m in names:
                        x[np.asarray(f, int), names.index(m)] = np.nan
        x = shift_clock(x, time, shift)
        cols, out_names = [x], list(names)
        for t in terms:
            if t.cause == "marker_slip" and t.channel in names:
                m = names.index(t.channel)
                k = slip_sample(t, time)
                second = np.full((time.size, 1, 3), np.nan)
                second[k:, 0] = x[k:, m]
                x = np.array(x, float) if not x.flags.writeable else x
                x[k:, m] = np.nan
                spec = specs[t.channel]
                name = t.channel + SLIP
                extra.append(MarkerSpec(name, spec.link, np.asarray(spec.xyz, float) + t.values))
                slips[name] = (t.channel, k)
                cols.append(second)
                out_names.append(name)
        cols[0] = x
        streams["markers"] = make_stream(tuple(out_names), np.concatenate(cols, axis=1) if len(cols) > 1 else x)
    robot2 = offset_robot(robot, offsets, extra, geometry) if (offsets or extra or geometry) else robot
    log2 = replace(log, streams={**log.streams, **streams}, truth=None)
    return Applied(log2, robot2, slips, shift, time, names)


def with_slip_markers(cal, applied: Applied, terms):
    """A Calibration with the second marker of each slip added (at its marker's xyz + the slip)."""
    if not applied.slips:
        return cal
    by = {t.channel: t for t in terms if t.cause == "marker_slip"}
    names, links, xyz = list(cal.marker_names), list(cal.marker_links), [cal.marker_xyz]
    se = [cal.marker_xyz_se if cal.marker_xyz_se is not None else np.full_like(cal.marker_xyz, np.nan)]
    for name, (orig, _) in applied.slips.items():
        if name in names:
            continue
        i = names.index(orig)
        names.append(name)
        links.append(links[i])
        xyz.append((cal.marker_xyz[i] + by[orig].values)[None])
        se.append(np.full((1, 3), np.nan))
    return replace(
        cal,
        marker_names=tuple(names),
        marker_links=tuple(links),
        marker_xyz=np.vstack(xyz),
        marker_xyz_se=np.vstack(se),
        marker_xyz_cov=None,  # of the markers before the split
    )


def to_log_markers(applied: Applied, names, x: np.ndarray) -> np.ndarray:
    """Marker values (T, M', 3) over the mapped log's markers ``names`` -> (T, M, 3) over the log's
    own markers, a slipped marker's second marker merged back from its slip sample on, on the
    log's (mocap) clock."""
    names = list(names)
    out = np.stack([x[:, names.index(n)] for n in applied.marker_names], axis=1) if applied.marker_names else x
    for name, (orig, k) in applied.slips.items():
        out[k:, applied.marker_names.index(orig)] = x[k:, names.index(name)]
    return shift_clock(out, applied.time, -applied.shift)
