"""Held-out error of a static-pose calibration over contiguous pose folds.

The poses (:func:`diegocal.stac.static.static_poses`) are cut into ``folds`` contiguous runs;
each run is predicted from its pots (eq. 2.11-2.12 at the q the pots give, :func:`diegocal.stac.predict.predict`)
by a calibration fitted on the others. Contiguous runs rather than single poses: neighbouring
poses of a session share its drifts, so a pose left out alone flatters the model (with as many
folds as poses it is leave-one-pose-out). ``stac --geometry --cv`` and
``bench/bench_static_calibration.py`` report it; every method of the bench is scored on the
same folds.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from diegocal.errors import DiegocalError, FitError
from diegocal.io import Log
from diegocal.robot import Robot
from diegocal.stac.pose_cv import PoseCV
from diegocal.stac.predict import predict
from diegocal.stac.static import static_poses, take

LOG = logging.getLogger(__name__)

#: Folds of ``stac --geometry --cv`` (the issue's protocol: ten contiguous folds).
FOLDS = 10


@dataclass(frozen=True)
class FoldCV(PoseCV):
    """Held-out marker error per pose, each pose held out with its fold.

    As :class:`~diegocal.stac.pose_cv.PoseCV` (error: by a calibration fitted without the pose's
    fold), and fold : (K,) the fold that held each pose out; folds : number of folds.
    """

    fold: np.ndarray = None
    folds: int = FOLDS

    def to_dict(self) -> dict:
        return {
            "kind": f"{self.folds} contiguous pose folds",
            "marker_error": {"mean": self.mean, "median": self.median, "max": self.worst},
            "poses": [
                {"pose": int(k), "start": float(t), "samples": int(n), "fold": int(f), "marker_error": float(e)}
                for k, t, n, f, e in zip(self.pose, self.start, self.samples, self.fold, self.error, strict=True)
            ],
        }


def fold_of(n_poses: int, folds: int) -> np.ndarray:
    """The fold (n_poses,) int of each pose: ``folds`` contiguous runs of near-equal length."""
    return np.minimum((np.arange(n_poses) * folds) // max(n_poses, 1), folds - 1)


def pose_folds(
    log: Log,
    robot: Robot,
    fit: Callable,
    options=None,
    folds: int = FOLDS,
    poses: np.ndarray | None = None,
    progress=None,
) -> FoldCV:
    """Fit ``fit(train_log, robot, options) -> Calibration`` without each contiguous fold of poses and
    predict the fold's markers from its pots (module docstring). ``poses`` (T,) int defaults to
    :func:`static_poses`; ``progress(k, folds)`` is called before each fit. Raises FitError for a
    log that is not static poses or has fewer poses than 2 × folds."""
    log = log.without_truth()
    if poses is None:
        poses = static_poses(log)
        if poses is None:
            raise FitError("--cv needs static poses: this log's pots drift within its holds like a moving session's")
    poses = np.asarray(poses, int)
    ids = np.unique(poses)
    folds = min(int(folds), len(ids))
    if len(ids) < 2 * folds or folds < 2:
        raise FitError(
            f"--cv needs at least {2 * max(folds, 2)} static poses for {max(folds, 2)} folds; the log has {len(ids)}"
        )
    fold = fold_of(len(ids), folds)
    fold_sample = fold[np.searchsorted(ids, poses)]
    x = log.stream("markers").data
    names = list(log.stream("markers").names)
    dist = np.full(log.n_samples, np.nan)
    for f in range(folds):
        if progress is not None:
            progress(f, folds)
        held = fold_sample == f
        test = take(log, np.flatnonzero(held))
        try:
            cal = fit(take(log, np.flatnonzero(~held)), robot, options)
            pred = predict(test, robot, cal, ("pots",), ("markers",))
        except DiegocalError as exc:  # one fold's fit failing leaves its poses NaN, not the others'
            LOG.warning(f"pose folds: the fit without fold {f} failed ({exc})")
            continue
        xp = pred.markers[:, [list(pred.marker_names).index(n) for n in names]]
        with np.errstate(invalid="ignore"):
            dist[held] = np.nanmean(np.linalg.norm(xp - x[held], axis=-1), axis=1)
    with np.errstate(invalid="ignore"):
        error = np.array([np.nanmean(dist[poses == k]) if np.isfinite(dist[poses == k]).any() else np.nan for k in ids])
    first = np.array([np.flatnonzero(poses == k)[0] for k in ids])
    return FoldCV(ids, log.time[first], np.array([(poses == k).sum() for k in ids]), error, fold=fold, folds=folds)
