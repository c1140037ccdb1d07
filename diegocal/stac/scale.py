"""Is the log in the units the robot's sensors.yaml states? Markers in m, pots in its gains' unit.

A log in mm, or pots read in mV against gains in V/rad, fits with a 'converged' calibration of
markers metres away, or gains a thousand times the nominal ones: each stream's spread is compared
with what the robot can produce and the log refused with one line when it is far past it.
"""

from __future__ import annotations

import numpy as np

from diegocal.errors import LogFormatError
from diegocal.robot import Robot

#: How many times the span the robot's markers can have the log's markers may spread before the
#: log is taken for one in mm (:func:`check_marker_scale`): mm read as m are 1000 times too far apart
SPAN_FACTOR = 10.0
#: How many times the range sensors.yaml's gains allow over the joints' limits the log's pots may
#: vary before the log is taken for one in another unit (:func:`check_pot_scale`): mV read as V vary
#: 1000 times as much; a gain some times off the nominal one is what calibration is for
POT_FACTOR = 30.0


def marker_spread(markers: np.ndarray) -> float:
    """How far the recorded markers (T, M, 3) m (NaN = occluded) lie from their centroid, m: the 90th
    percentile of their distances from the per-axis median (ghost markers and swapped labels, a few
    percent of the readings, do not count); 0 with fewer than two readings. A spread, not a
    position: the mocap frame may lie anywhere."""
    x = markers[np.isfinite(markers).all(axis=-1)]
    if len(x) < 2:
        return 0.0
    return float(np.quantile(np.linalg.norm(x - np.median(x, axis=0), axis=1), 0.9))


def marker_span(robot: Robot, specs) -> float:
    """An upper bound, m, on the distance between two of the markers ``specs`` over every joint
    angle: the lengths of the joint placements on the links' chains (a prismatic joint's travel
    added, inf when it has no limit), plus twice the farthest marker from its joint (its link's
    offset and its nominal position). The markers' centroid lies within it of each of them."""
    model, joints, reach = robot.model, set(), 0.0
    for m in specs:
        frame = model.frames[robot.frame_id(m.link)]
        joints.update(j for j in model.supports[frame.parentJoint] if j > 0)
        reach = max(reach, np.linalg.norm(frame.placement.translation) + np.linalg.norm(m.xyz))
    span = 2.0 * reach
    for j in joints:
        span += np.linalg.norm(model.jointPlacements[j].translation)
        if model.names[j] in robot.prismatic_joints:
            span += max(abs(robot.lower[j - 1]), abs(robot.upper[j - 1]))  # inf: no limit, no check
    return float(span)


def check_marker_scale(markers: np.ndarray, robot: Robot, specs) -> None:
    """Raise LogFormatError when the markers (T, M, 3) spread (:func:`marker_spread`) over
    :data:`SPAN_FACTOR` times what the robot can span between them (:func:`marker_span`): a log in
    mm (or cm), which would otherwise fit with a 'converged' calibration of markers metres away."""
    spread = marker_spread(markers)
    span = marker_span(robot, specs)
    if spread > SPAN_FACTOR * span:
        raise LogFormatError(
            f"the log's markers spread {spread:.4g} m from their centroid, over {SPAN_FACTOR:g}× what robot "
            f"{robot.name!r} can span between them ({span:.3g} m at most): markers in mm? the log wants m "
            "(convert them, or import with the mocap file's unit)"
        )


def pot_range(robot: Robot, specs, A: np.ndarray) -> np.ndarray:
    """(P,) the range each pot's reading can span by its nominal gain over the joints' limits:
    |gain| Σ_j |A_pj| (upper_j − lower_j) for rotary, encoder and tendon pots (``A``: s = A q,
    :func:`~diegocal.stac.model._linear_map`); NaN for a linear pot (its span is the geometry's) and
    where a joint it reads has no limit (a continuous joint too)."""
    width = np.asarray(robot.upper, float) - np.asarray(robot.lower, float)
    for j in getattr(robot, "continuous", ()):  # a wheel's ±π are not limits: it turns without end
        width[robot.joint_index(j)] = np.inf
    out = np.full(len(specs), np.nan)
    for i, p in enumerate(specs):
        if p.kind == "linear":
            continue
        reads = np.abs(A[i]) > 0
        if reads.any() and np.isfinite(width[reads]).all():
            out[i] = abs(p.gain) * float(np.abs(A[i, reads]) @ width[reads])
    return out


def check_pot_scale(pots: np.ndarray, robot: Robot, specs, A: np.ndarray) -> None:
    """Raise LogFormatError when the log's pots (T, P) vary, by the median over the pots, over
    :data:`POT_FACTOR` times the range their nominal gains allow (:func:`pot_range`): a whole stream
    in another unit than the gains' (mV for V). A pot's variation is its readings' 1st to 99th
    percentile (a glitch does not count)."""
    span = pot_range(robot, specs, A)
    ok = np.isfinite(span) & (span > 0)
    if not ok.any() or pots.shape[0] < 2:
        return
    lo, hi = np.nanpercentile(pots[:, ok], [1.0, 99.0], axis=0)
    ratio = float(np.median((hi - lo) / span[ok]))
    if ratio > POT_FACTOR:
        raise LogFormatError(
            f"the log's pots vary {ratio:.3g}× the range sensors.yaml's gains allow over the joint limits of "
            f"robot {robot.name!r} (the median over the pots): readings in another unit than the gains "
            "(mV against V/rad?): convert them, import them with their unit (`unit: mV`), or state the gains "
            "in the readings' unit"
        )
