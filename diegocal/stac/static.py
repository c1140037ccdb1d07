"""Static-pose calibrations: the poses in a log.

Labs often calibrate from tens of static poses: the robot held still in each (encoders with gain 1,
a rigid marker cluster on the end effector, the mocap frame unknown). STAC needs nothing special
for them (a pose is one or a few frames; joint offsets are the encoders' biases, the cluster the
marker positions, eq. 2.10), and it writes off poses filed with another pose's mocap frame
(:mod:`diegocal.stac.poses`, which needs the poses found here). What this module adds:

* :func:`find_poses` cuts a log into poses: a new pose begins where some pot moves by more than
  POSE_SIGMAS times its noise between two samples (:func:`pot_noise`: a robust scale of the
  sample-to-sample changes, which within a held pose are noise alone), so pot noise never splits
  a pose, and two poses closer than that in every pot are one; a log whose consecutive samples
  are as different as any two (one sample per pose: snapshots) has as many poses as samples;
* :func:`static_poses` says whether a log is static poses at all (snapshots, or holds whose
  readings scatter like noise rather than drift like motion): STAC checks the poses of such a
  log for markers that are not their own (:mod:`diegocal.stac.poses`);
* :func:`take` keeps some samples of a log (:mod:`diegocal.stac.pose_cv` holds poses out with it).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from diegocal.io import Log, Stream

#: A pot moving by more than this many times its noise between two samples starts a new pose
#: (the change of two noisy readings has σ √2; a Gaussian tail of 2e-9 per pot and sample).
POSE_SIGMAS = 6.0
#: Consecutive samples are snapshots (each its own pose) when every moving pot's sample-to-sample
#: scale (:func:`pot_noise`) is at least this fraction of its spread over the log: they then
#: differ as much as any two samples (random poses give about 1; holds or motion, far less).
SNAPSHOT_RATIO = 0.5
#: Snapshots may have a few pots held at a few values (a chosen pose set): the share of moving
#: pots that must look random (SNAPSHOT_RATIO) for the others to be judged by their jumps.
SNAPSHOT_SHARE = 0.75
#: Poses are static holds, not stretches of motion, when every pot's von Neumann ratio within
#: them (mean squared change over twice the variance about the pose's mean; 1 for noise, near 0
#: for a drifting or moving reading) is at least this.
STATIC_RATIO = 0.5


def pot_noise(p: np.ndarray) -> np.ndarray:
    """Noise σ (P,) of each pot, in its unit, from readings p (T, P): 1.4826 · median |Δp| / √2,
    the robust scale of the sample-to-sample changes (noise alone when most changes are within a
    held pose), at least the smallest non-zero change (a quantised reading's step)."""
    d = np.abs(np.diff(p, axis=0))
    if d.shape[0] == 0:
        return np.zeros(p.shape[1])
    step = np.array([c[c > 0].min() if (c > 0).any() else 0.0 for c in d.T])
    return np.maximum(1.4826 * np.median(d, axis=0) / np.sqrt(2.0), step)


def _snapshots(p: np.ndarray, noise: np.ndarray) -> bool:
    """Whether consecutive samples of p (T, P) are unrelated (see SNAPSHOT_RATIO): every moving
    pot's sample-to-sample scale is a fair share of its spread; or most are (SNAPSHOT_SHARE) and
    each of the others jumps by that share somewhere, as a joint held at a few values does between
    chosen poses (a torso at zero, a joint at its limits), never a joint moving in a session."""
    spread = np.std(p, axis=0)
    moving = spread > 0
    if not moving.any():
        return False
    random = noise[moving] >= SNAPSHOT_RATIO * spread[moving]
    if random.all():
        return True
    jumps = np.abs(np.diff(p[:, moving], axis=0)).max(axis=0) >= SNAPSHOT_RATIO * spread[moving]
    return bool(random.mean() >= SNAPSHOT_SHARE and jumps[~random].all())


def find_poses(log: Log, noise: np.ndarray | None = None) -> np.ndarray:
    """Pose index of every sample (T,) int, 0-based, from the log's ``pots`` stream.

    ``noise`` (P,) is each pot's noise σ in its unit (default :func:`pot_noise` of the log): a
    pose ends where some pot moves by more than POSE_SIGMAS √2 σ between two samples. Snapshots
    (SNAPSHOT_RATIO) are one pose per sample.
    """
    p = log.stream("pots", needed_by="stac --cv").data
    if p.shape[0] < 2:
        return np.zeros(p.shape[0], dtype=int)
    if noise is None:
        noise = pot_noise(p)
        if _snapshots(p, noise):
            return np.arange(p.shape[0])
    limit = POSE_SIGMAS * np.sqrt(2.0) * np.asarray(noise, float)
    step = np.abs(np.diff(p, axis=0)) > limit
    return np.concatenate([[0], np.cumsum(step.any(axis=1))]).astype(int)


def static_poses(log: Log) -> np.ndarray | None:
    """The poses (T,) int of a static-pose log (:func:`find_poses`), or None when the log is not
    one: its pots move within the stretches :func:`find_poses` cuts (STATIC_RATIO), as a moving
    session's do, or it has no pots."""
    if not log.has("pots") or log.n_samples < 2:
        return None
    p = log.stream("pots").data
    poses = find_poses(log)
    if len(np.unique(poses)) == len(poses):
        return poses  # snapshots: one sample per pose
    mean = np.zeros((poses.max() + 1, p.shape[1]))
    np.add.at(mean, poses, p)
    count = np.bincount(poses)
    mean /= count[:, None]
    same = poses[1:] == poses[:-1]
    if not same.any():
        return poses
    msd = np.mean(np.diff(p, axis=0)[same] ** 2, axis=0)
    var = np.sum((p - mean[poses]) ** 2, axis=0) / max(int(np.sum(count - 1)), 1)
    ratio = msd / np.maximum(2.0 * var, 1e-300)
    return poses if np.all(ratio[var > 0] >= STATIC_RATIO) else None


def take(log: Log, index: np.ndarray) -> Log:
    """The samples ``index`` (sorted) of every stream (no truth: fitting never reads it)."""
    streams = {k: Stream(s.names, s.data[index]) for k, s in log.streams.items()}
    return replace(log, time=log.time[index], streams=streams, truth=None)
