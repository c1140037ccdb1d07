"""A log's joint streams (q, qd, qdd, tau) as arrays in a robot's joint order.

A log may carry channels the robot model does not move: a gripper's motor beside an arm's joints,
or a joint the model holds still (:attr:`diegocal.robot.Robot.locked`: sensors.yaml locks it, or no
sensor and no stream used it when the robot was loaded). Those channels are left out with one
warning that names them and, for a locked joint, says at what and why it is held (its motion is
not modelled); they are not an error. A robot joint without a channel is one in q, qd and qdd
(the regressor needs every joint's motion), and in tau only leaves that joint's torque unfitted.

Angles are checked against the URDF's limits (:func:`check_angles`): revolute joints recorded far
outside them, and within them read as degrees, are a log in degrees, one error line; any other
excursion is one warning line. A torque clipped by a sensor's range or a drive's limit has its
samples at the limit left out (:func:`without_clipped`).
"""

from __future__ import annotations

import difflib
import logging

import numpy as np

from diegocal.errors import LogFormatError, MissingStreamError
from diegocal.sgp.options import INPUT_STREAMS
from diegocal.sgp.regressor import nominal_torque

LOG = logging.getLogger(__name__)
#: rad a revolute joint may read past its URDF limits before a warning says so (a sensor zeroed a
#: little off reads past its hard stop)
LIMIT_TOLERANCE = 0.01
#: rad past its limits (at least; else the joint's own range, when larger) that only a log in
#: degrees explains: 2π, one turn
GROSS_EXCURSION = 2 * np.pi


def unused_channels(log, robot, streams) -> dict[str, list[str]]:
    """{channel: [streams]} of the log's channels in ``streams`` that are not joints of ``robot``."""
    out: dict[str, list[str]] = {}
    for name in streams:
        if log.has(name):
            for c in log.streams[name].names:
                if c not in robot.joint_names:
                    out.setdefault(c, []).append(name)
    return out


def unused_line(unused: dict, robot) -> str:
    """One warning line naming the channels :func:`unused_channels` found, and why each is left out."""
    sensors_locked = getattr(robot.sensors, "locked", None) or {}
    parts = []
    for c, where in unused.items():
        what = f"{c} ({', '.join(where)})"
        if c in robot.locked:
            why = (
                "sensors.yaml locks it" if c in sensors_locked
                else "no sensor and no stream used it when the robot was loaded"
            )
            value = robot.locked[c]
            shown = f"{value:g}" if isinstance(value, float) else str(value)
            what += f": a joint the model holds still at {shown} ({why}), so its motion is not modelled"
        else:
            match = difflib.get_close_matches(c, list(robot.joint_names), n=1, cutoff=0.75)
            if match:
                what += f" — did you mean {match[0]!r}?"
        parts.append(what)
    return f"ignored log channel(s) that are not joints of robot {robot.name!r}: {'; '.join(parts)}"


def warn_unused(log, robot, streams) -> None:
    """Warn once about the channels of ``streams`` that are left out (:func:`unused_line`)."""
    unused = unused_channels(log, robot, streams)
    if unused:
        LOG.warning(unused_line(unused, robot))


def torque_array(log, robot, warn: bool = True) -> tuple[np.ndarray, tuple]:
    """The ``tau`` stream's columns of the robot's joints, in the robot's joint order.

    Returns (tau (T, k), joint names (k,)): every joint that has a torque channel. A joint without
    one (e.g. TIAGo's wrists, whose efforts are unusable) is simply absent, so that a model can be
    fitted on the rows of the joints that have a torque; channels that are no joint of the robot
    are left out with a warning (``warn``); a stream with no joint at all is a one-line error.
    Samples at a clipping limit are NaN, with a warning (:func:`without_clipped`).
    """
    s = log.stream("tau", needed_by="sgp-fit")
    if warn:
        warn_unused(log, robot, ("tau",))
    joints = tuple(j for j in robot.joint_names if j in s.names)
    if not joints:
        others = f" (its channels {', '.join(s.names)} are not joints of it)" if s.names else ""
        raise MissingStreamError(f"stream 'tau' has no channel of robot {robot.name!r}: nothing to fit{others}")
    return without_clipped(s.select(joints).data, joints), joints


#: A torque sits at a clipping limit when at least this share of its samples (and CLIP_MIN_SAMPLES)
#: reads its extreme value exactly, CLIP_RATIO times as many as read the next value in: a sensor's
#: range or a drive's current limit piles every sample beyond it onto one value, while a quantised
#: torque's smooth peak (a sine's: 2.4 times) spreads over the levels below.
CLIP_SHARE = 0.005
CLIP_MIN_SAMPLES = 10
CLIP_RATIO = 5.0


def clipped_samples(x: np.ndarray) -> np.ndarray:
    """(T,) bool: the samples of one torque channel that sit at a clipping limit (either end)."""
    out = np.zeros(x.shape, bool)
    finite = x[np.isfinite(x)]
    if finite.size == 0:
        return out
    values, counts = np.unique(finite, return_counts=True)
    need = max(CLIP_MIN_SAMPLES, CLIP_SHARE * finite.size)
    for end, nxt in ((-1, -2), (0, 1)):
        if values.size > 1 and counts[end] >= need and counts[end] >= CLIP_RATIO * counts[nxt]:
            out |= x == values[end]
    return out


def without_clipped(tau: np.ndarray, joints) -> np.ndarray:
    """``tau`` with the samples at a clipping limit NaN (left out of fits and scores), one warning
    per joint that has them: a clipped torque is no torque the model could predict."""
    out = None
    for k, j in enumerate(joints):
        bad = clipped_samples(tau[:, k])
        if bad.any():
            if out is None:
                out = np.array(tau, float, copy=True)
            limits = " and ".join(f"{v:.4g}" for v in np.unique(tau[bad, k]))
            LOG.warning(
                f"tau of {j} reads exactly {limits} N·m in {bad.mean():.1%} of the samples: clipped (a sensor's "
                "range, a drive's current limit)? Those samples are left out"
            )
            out[bad, k] = np.nan
    return tau if out is None else out


def check_angles(robot, q: np.ndarray, warn: bool = True) -> None:
    """Raise LogFormatError when q (T, n) rad (robot joint order; NaN ignored) is a log in degrees: a
    revolute joint with finite URDF limits reads farther outside them than its own range and
    :data:`GROSS_EXCURSION`, and every such joint read as degrees lies within them (widened as
    :class:`~diegocal.stac.model.Observation` widens them: a quarter of the range and 0.3 rad).
    With ``warn``, one warning line names the joints past their limits by more than
    :data:`LIMIT_TOLERANCE` otherwise (a joint the simulator let turn past them, too). Continuous and
    prismatic joints are not checked (a continuous joint turns without end; a prismatic one is in m)."""
    q = np.asarray(q, float)
    skip = frozenset(getattr(robot, "continuous", ())) | robot.prismatic_joints
    gross, past = [], []
    for i, j in enumerate(robot.joint_names):
        lo, hi = robot.lower[i], robot.upper[i]
        x = q[:, i][np.isfinite(q[:, i])]
        if j in skip or not (np.isfinite(lo) and np.isfinite(hi)) or x.size == 0:
            continue
        lo_q, hi_q = x.min(), x.max()
        excursion = max(lo - lo_q, hi_q - hi)
        if excursion > max(hi - lo, GROSS_EXCURSION):
            gross.append((excursion, j, lo_q, hi_q, lo, hi))
        if excursion > LIMIT_TOLERANCE:
            past.append(f"{j} [{lo_q:.3g}, {hi_q:.3g}] (limits [{lo:.3g}, {hi:.3g}])")
    if gross and all(_within_as_degrees(*g[2:]) for g in gross):
        _, j, lo_q, hi_q, lo, hi = max(gross)
        more = f" (and {len(gross) - 1} more joint(s))" if len(gross) > 1 else ""
        raise LogFormatError(
            f"joint {j!r}: the log's q spans [{lo_q:.4g}, {hi_q:.4g}], far outside its URDF limits "
            f"[{lo:.3g}, {hi:.3g}] rad{more}: degrees? the log wants rad (qd, qdd in rad/s, rad/s²)"
        )
    if warn and past:
        shown = "; ".join(past[:6]) + ("; ..." if len(past) > 6 else "")
        LOG.warning(f"q past the URDF limits of robot {robot.name!r} (rad): {shown}")


#: How many times the torque the URDF's rigid body needs for the log's motion (either way) the log's
#: torques may be, by the median over the joints, before the log is taken for one in another unit:
#: mN·m read as N·m are 1000 times it; friction and a wrong inertia make it some times it (the TX40's
#: median 2.6, its friction-bound wrist 96 times), a slow robot the gravity does not load more
TORQUE_FACTOR = 300.0
#: Samples of the log the check computes the rigid body's torque on (spread over the whole log)
TORQUE_CHECK_SAMPLES = 1000
#: kg: a URDF whose links weigh less in all has placeholder inertias, no scale for the torques
MIN_MASS = 0.1


def check_torque_scale(robot, q, qd, qdd, tau: np.ndarray, joints) -> None:
    """Raise LogFormatError when the torques ``tau`` (T, k) of ``joints`` are, by the median over the
    joints, over :data:`TORQUE_FACTOR` times (or under its inverse) what the URDF's rigid body needs
    for the log's motion (RNEA, no friction; each joint's median |τ|, which a noisy differentiated
    qdd moves little): a log in mN·m (or kN·m). Joints whose rigid-body torque is under 1 % of the
    largest joint's are not compared (a wrist turning about the vertical carries friction only); a
    URDF under :data:`MIN_MASS` in all (placeholder inertias) gives no scale, and no check."""
    if sum(robot.model.inertias[i].mass for i in range(1, robot.model.njoints)) < MIN_MASS:
        return
    T = len(q)
    rows = np.unique(np.linspace(0, T - 1, min(T, TORQUE_CHECK_SAMPLES)).astype(int))
    ok = np.isfinite(q[rows]).all(axis=1) & np.isfinite(qd[rows]).all(axis=1) & np.isfinite(qdd[rows]).all(axis=1)
    rows = rows[ok]
    if rows.size < 10:
        return
    at = [robot.joint_names.index(j) for j in joints]
    rigid = np.median(np.abs(nominal_torque(robot, q[rows], qd[rows], qdd[rows])[:, at]), axis=0)
    x = np.abs(tau[rows])
    measured = np.array([np.median(c[np.isfinite(c)]) if np.isfinite(c).any() else np.nan for c in x.T])
    use = (rigid > 0.01 * rigid.max()) & np.isfinite(measured) & (measured > 0)
    if not use.any():
        return
    ratio = float(np.median(measured[use] / rigid[use]))
    if ratio > TORQUE_FACTOR or ratio < 1.0 / TORQUE_FACTOR:
        raise LogFormatError(
            f"the log's torques are {ratio:.3g} times what the URDF of robot {robot.name!r} needs for its motion "
            f"(median |τ|, the median over the joints): {'mN·m' if ratio > 1 else 'kN·m'}? the log wants N·m (N "
            "for a prismatic joint); convert them, or import them with their unit"
        )


def _within_as_degrees(lo_q: float, hi_q: float, lo: float, hi: float) -> bool:
    """Whether the span [lo_q, hi_q] read as degrees lies within the limits [lo, hi] rad widened by a
    quarter of their range and 0.3 rad (the margin :class:`~diegocal.stac.model.Observation` allows)."""
    margin = 0.25 * (hi - lo) + 0.3
    return lo - margin <= np.radians(lo_q) and np.radians(hi_q) <= hi + margin


def log_arrays(log, robot, need_tau: bool = True, needed_by: str | None = None, warn: bool = True):
    """q, qd, qdd (and tau) of a log in the robot's joint order, (T, n) each; channels that are no
    joint of the robot are left out with one warning (``warn``); one-line errors naming
    ``needed_by`` (default: "sgp-fit" with tau, "sgp predict" without), and q checked against the
    URDF's limits (:func:`check_angles`: degrees are an error, a small excursion a warning)."""
    needed_by = needed_by or ("sgp-fit" if need_tau else "sgp predict")
    names = INPUT_STREAMS + (("tau",) if need_tau else ())
    out = []
    for name in names:
        s = log.stream(name, needed_by=needed_by)
        missing = [j for j in robot.joint_names if j not in s.names]
        if missing:
            raise MissingStreamError(f"stream '{name}' lacks joint(s) {missing} of robot {robot.name!r}")
        out.append(s.select(robot.joint_names).data)
    if warn:
        warn_unused(log, robot, names)
    check_angles(robot, out[0], warn=warn)
    return tuple(out)
