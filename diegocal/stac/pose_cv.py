"""Leave-one-pose-out cross-validation of a static-pose calibration.

:func:`leave_one_pose_out` calibrates without each pose in turn and predicts that pose's markers
from its pots (thesis §2.7.2's cross-sensor prediction, eq. 2.11-2.12 at the q the pots give): its
mean marker distance is the error a new pose will see, pose by pose, so a pose whose markers are
not its own stands out. Poses are those of :func:`diegocal.stac.static.static_poses`.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from diegocal.errors import DiegocalError, FitError
from diegocal.io import Log
from diegocal.robot import Robot
from diegocal.stac.predict import predict
from diegocal.stac.result import StacOptions
from diegocal.stac.stac import calibrate
from diegocal.stac.static import static_poses, take

LOG = logging.getLogger(__name__)


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

    @property
    def worst(self) -> float:
        return float(np.nanmax(self.error))

    def outliers(self, factor: float = 5.0) -> np.ndarray:
        """Poses whose error exceeds ``factor`` times the median: (k,) pose indices."""
        return self.pose[self.error > factor * self.median]

    def to_dict(self) -> dict:
        return {
            "kind": "leave-one-pose-out",
            "marker_error": {"mean": self.mean, "median": self.median, "max": self.worst},
            "poses": [
                {"pose": int(k), "start": float(t), "samples": int(n), "marker_error": float(e)}
                for k, t, n, e in zip(self.pose, self.start, self.samples, self.error, strict=True)
            ],
        }


def leave_one_pose_out(
    log: Log, robot: Robot, options: StacOptions | None = None, poses: np.ndarray | None = None, progress=None
) -> PoseCV:
    """Calibrate without each pose and predict its markers from its pots (see the module docstring).

    ``poses`` (T,) int defaults to :func:`static_poses`; every sample of a pose is held out
    together. ``progress(k, K)`` is called before each fit. Raises FitError for a log that is not
    static poses (no ``poses`` given) or has fewer than 3.
    """
    options = options or StacOptions()
    log = log.without_truth()
    if poses is None:
        poses = static_poses(log)
        if poses is None:
            raise FitError(
                "leave-one-pose-out needs static poses: this log's pots drift within its holds like a moving "
                "session's (each held pose must read as noise around one value)"
            )
    poses = np.asarray(poses, dtype=int)
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
