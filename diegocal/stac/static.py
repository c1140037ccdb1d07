"""Static-pose calibrations: poses in a log, and the leave-one-pose-out marker error.

Labs often calibrate from tens of static poses: the robot held still in each (encoders with gain 1,
a rigid marker cluster on the end effector, the mocap frame unknown). STAC needs nothing special
for them (a pose is one or a few frames; joint offsets are the encoders' biases, the cluster the
marker positions, eq. 2.10), and with a robust loss it writes off poses filed with another pose's
mocap frame (:func:`diegocal.stac.robust.gross_frames`). What it adds is the evaluation:

* :func:`find_poses` cuts a log into poses: a new pose begins where any pot moves by more than
  POSE_TOL of its range between two samples (a log of one sample per pose has as many poses as
  samples);
* :func:`leave_one_pose_out` calibrates without each pose in turn and predicts that pose's markers
  from its pots (thesis §2.7.2's cross-sensor prediction, eq. 2.11-2.12 at the q the pots give):
  its mean marker distance is the error a new pose will see, pose by pose, so a pose whose markers
  are not its own stands out.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, replace

import numpy as np

from diegocal.errors import DiegocalError, FitError
from diegocal.io import Log, Stream
from diegocal.robot import Robot
from diegocal.stac.result import StacOptions

LOG = logging.getLogger(__name__)

#: A pot moving by more than this fraction of its range between two samples starts a new pose.
POSE_TOL = 0.01


def find_poses(log: Log, tol: float = POSE_TOL) -> np.ndarray:
    """Pose index of every sample (T,) int, 0-based, from the log's ``pots`` stream."""
    p = log.stream("pots", needed_by="stac --cv").data
    if p.shape[0] < 2:
        return np.zeros(p.shape[0], dtype=int)
    span = np.ptp(p, axis=0)
    step = np.abs(np.diff(p, axis=0)) > tol * np.where(span > 0, span, np.inf)
    return np.concatenate([[0], np.cumsum(step.any(axis=1))]).astype(int)


def take(log: Log, index: np.ndarray) -> Log:
    """The samples ``index`` (sorted) of every stream (no truth: fitting never reads it)."""
    streams = {k: Stream(s.names, s.data[index]) for k, s in log.streams.items()}
    return replace(log, time=log.time[index], streams=streams, truth=None)


@dataclass(frozen=True)
class PoseCV:
    """Leave-one-pose-out marker error.

    Attributes
    ----------
    pose : (K,) int, pose index; start : (K,) s, its first sample's time; samples : (K,) int
    error : (K,) m, mean distance between the pose's markers and their prediction from its pots by
        a calibration fitted without it (NaN where the pose has no visible marker or that fit failed)
    """

    pose: np.ndarray
    start: np.ndarray
    samples: np.ndarray
    error: np.ndarray

    @property
    def mean(self) -> float:
        return float(np.nanmean(self.error))

    @property
    def median(self) -> float:
        return float(np.nanmedian(self.error))

    def outliers(self, factor: float = 5.0) -> np.ndarray:
        """Poses whose error exceeds ``factor`` times the median: (k,) pose indices."""
        return self.pose[self.error > factor * self.median]

    def to_dict(self) -> dict:
        return {
            "kind": "leave-one-pose-out",
            "marker_error": {"mean": self.mean, "median": self.median, "max": float(np.nanmax(self.error))},
            "poses": [
                {"pose": int(k), "start": float(t), "samples": int(n), "marker_error": float(e)}
                for k, t, n, e in zip(self.pose, self.start, self.samples, self.error, strict=True)
            ],
        }


def leave_one_pose_out(
    log: Log, robot: Robot, options: StacOptions | None = None, poses: np.ndarray | None = None, progress=None
) -> PoseCV:
    """Calibrate without each pose and predict its markers from its pots (see the module docstring).

    ``poses`` (T,) int defaults to :func:`find_poses`; ``progress(k, K)`` is called before each fit.
    Raises FitError with fewer than 3 poses.
    """
    from diegocal.stac.predict import predict
    from diegocal.stac.stac import calibrate

    options = options or StacOptions()
    log = log.without_truth()
    poses = find_poses(log) if poses is None else np.asarray(poses, dtype=int)
    ids = np.unique(poses)
    if len(ids) < 3:
        raise FitError(f"leave-one-pose-out needs at least 3 poses; the log has {len(ids)}")
    error = np.full(len(ids), np.nan)
    for i, k in enumerate(ids):
        if progress is not None:
            progress(i, len(ids))
        held = poses == k
        test = take(log, np.flatnonzero(held))
        if not np.isfinite(test.stream("markers").data).all(axis=-1).any():
            continue
        try:
            cal = calibrate(take(log, np.flatnonzero(~held)), robot, options).calibration
            error[i] = predict(test, robot, cal, ("pots",), ("markers",), options).mae["markers"]
        except DiegocalError as exc:  # one pose's fit failing leaves its error NaN, not the others'
            LOG.warning(f"leave-one-pose-out: the fit without pose {k} failed ({exc})")
    first = np.array([np.flatnonzero(poses == k)[0] for k in ids])
    return PoseCV(ids, log.time[first], np.array([(poses == k).sum() for k in ids]), error)
