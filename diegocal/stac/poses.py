"""Static poses whose markers are not their own: found by their disagreement with the rest, and
written off.

A static-pose session recorded while the mocap clock drifted files some poses with another pose's
markers. Each such pose is a block of readings whose markers and pots disagree far beyond their
noise, and there may be many (a quarter of the poses), beyond what a robust loss on single
readings survives (:mod:`.robust`: about 10 %). On a log that :func:`~.static.static_poses` calls
static, STAC therefore checks every pose after the fit and refits without the markers of the
poses that disagree:

* each pose's disagreement D_k is the sum of the squared standardised residuals of its readings
  (pots and markers) at joint angles tracked from all of them, with θ fixed at a calibration fitted
  without the markers of the poses written off so far (for those, a leave-out residual). The
  scales are high-breakdown ones from the poses kept: 1.4826 · median |r| per pot (the MAD about
  zero, as :func:`~.robust.gross_frames`) and per marker ‖r‖² over its median under χ²_3, so that
  a corrupted first fit (σ inflated by the wrong poses) does not hide them;
* a pose disagrees when D_k exceeds the 1 − POSE_TAIL quantile of χ²_N (N: its readings);
* each round writes off the markers of every pose that disagrees and readmits those that now
  agree, and refits, until the set stops changing (at most MAX_ROUNDS; never more than half the
  poses, the worst first). A fit spoiled by the wrong poses can make a few good ones disagree
  too; the next round, fitted without the wrong ones, readmits them (writing off only the worst
  few per round instead took more rounds, each a fit, for the same answer).

Pose k's markers are then treated as occluded (its pots still track its joints), and the pose is
listed in the calibration's ``rejected_poses`` with its ratio.
"""

from __future__ import annotations

import logging
from collections.abc import Callable

import numpy as np
from scipy.special import chdtri  # the chi-square isf: no scipy.stats import

from diegocal.errors import DiegocalError
from diegocal.stac.model import MARKERS, Observation, Params
from diegocal.stac.qphase import Noise, pot_sigmas
from diegocal.stac.result import StacOptions
from diegocal.stac.track import track

LOG = logging.getLogger(__name__)

#: A pose disagrees when its D_k passes this tail probability of χ²_N: 1e-6, as for single frames
#: (:data:`diegocal.stac.robust.GROSS_TAIL`), so a clean session of hundreds of poses flags none.
POSE_TAIL = 1e-6
#: Rounds of "write off, readmit, refit" at most.
MAX_ROUNDS = 10
#: LM steps of the tracking at fixed θ (it stops earlier once every frame's step is rejected).
TRACK_STEPS = 40


def disagreement(
    obs: Observation,
    params: Params,
    sigma: dict,
    q: np.ndarray,
    poses: np.ndarray,
    kept: np.ndarray,
    options: StacOptions,
) -> np.ndarray:
    """D_k over its χ²_N quantile (K,) for every pose (see the module docstring).

    ``obs``: the Observation with every marker (none written off); ``params``, ``sigma``: the
    calibration; ``q`` (T, n) rad: the joint angles to start the tracking from; ``poses`` (T,) int
    0..K-1; ``kept`` (T,) bool: the frames whose residuals set the robust scales.
    """
    noise = Noise(pot_sigmas(obs, sigma), sigma.get(MARKERS, 1.0))
    q, st = track(obs, params, noise, q, TRACK_STEPS, options.batch_size, options.jobs)
    use = ~obs.fixed_gain  # pots held at nominal fit their joints exactly: no evidence
    rp = (params.gain * st.s + params.bias - obs.pots)[:, use]
    scale = 1.4826 * np.median(np.abs(rp[kept]), axis=0) if kept.any() else np.full(rp.shape[1], np.inf)
    zp2 = (rp / np.maximum(scale, 1e-12)) ** 2
    xb = np.einsum("tmij,mj->tmi", st.Rl, params.xyz) + st.pl
    sq = np.sum((xb @ params.R.T + params.T - np.nan_to_num(obs.markers)) ** 2, axis=-1)  # (T, M)
    seen = obs.valid & kept[:, None]
    med = np.array([np.median(sq[seen[:, m], m]) if seen[:, m].any() else np.inf for m in range(obs.n_markers)])
    valid = obs.valid & np.isfinite(med)
    zx2 = np.where(valid, sq / np.maximum(med / chdtri(3, 0.5), 1e-24), 0.0)
    frame_d = zp2.sum(axis=1) + zx2.sum(axis=1)
    frame_n = use.sum() + 3 * valid.sum(axis=1)
    d = np.bincount(poses, frame_d)
    n = np.bincount(poses, frame_n)
    return d / chdtri(np.maximum(n, 1), POSE_TAIL)


def _decide(ratio: np.ndarray) -> np.ndarray:
    """The poses to write off next (K,) bool from their ratios D_k / quantile."""
    new = ratio > 1.0  # the kept poses that disagree go; written-off ones that now agree return
    limit = (len(ratio) - 1) // 2  # a majority of poses stays: the scales need it
    if new.sum() > limit:
        keep = np.argsort(-np.where(new, ratio, -np.inf))[:limit]
        new = np.zeros_like(new)
        new[keep] = True
    return new


def write_off_foreign_poses(
    base: Observation, obs: Observation, stage, poses: np.ndarray, refit: Callable, options: StacOptions
):
    """Check the poses of a static-pose log and refit without those that disagree (module docstring).

    ``base``: the Observation with every marker; ``obs`` and ``stage``: the fit made on it (its
    Observation, possibly with frames a robust loss wrote off, and the :class:`~.stac._Stage`);
    ``poses`` (T,) int 0..K-1; ``refit(observation)`` fits again and returns (Observation, stage).
    Returns the final (Observation, stage); the Observation's ``rejected_poses`` lists the poses
    written off as ``{pose, frame (the first), samples, disagreement (D_k over its quantile)}``.
    """
    K = int(poses.max()) + 1
    frames = np.arange(base.n_frames)
    out = np.zeros(K, dtype=bool)
    ratio = np.zeros(K)
    for _ in range(MAX_ROUNDS):
        kept = ~out[poses] & ~np.isin(frames, obs.rejected)
        ratio = disagreement(base, stage.params, stage.sigma, stage.q, poses, kept, options)
        new = _decide(ratio)
        if np.array_equal(new, out):
            break
        try:
            obs, stage = refit(base.without_poses(new[poses]))
        except DiegocalError as exc:  # a refit without those markers failing keeps the last fit
            LOG.warning(f"the fit without the markers of {int(new.sum())} disagreeing pose(s) failed ({exc})")
            break
        out = new
    first = np.searchsorted(poses, np.arange(K))  # poses are numbered in time order
    count = np.bincount(poses, minlength=K)
    records = tuple(
        {"pose": int(k), "frame": int(first[k]), "samples": int(count[k]), "disagreement": float(ratio[k])}
        for k in np.flatnonzero(out)
    )
    return obs.with_rejected_poses(records), stage
