"""One evaluation module for every model family: contiguous blocks, held-out scores, the rule
that chooses by validation.

Samples 10 ms apart are not independent, so nothing here treats them as if they were:

- :func:`split_blocks` cuts a log into contiguous blocks in time and gives each a role,
  ``train``, ``validation`` or ``heldout``, interleaved so that every role sees the whole session;
- :func:`score` gives one :class:`Score` per evaluation (per channel RMSE, nMSE, MAE, coverage of
  the ±2σ band), whatever the domain: torques, pot readings, marker positions, pressures;
- :func:`block_mse` and :func:`paired_se` give errors per block and the standard error of a paired
  difference between two models over blocks (the block, not the sample, is the unit);
- :func:`choose_by_validation` is the one-standard-error rule (Hastie et al., *Elements of
  Statistical Learning* §7.10) that the SGP guard and ``diagnose`` use.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

ROLES = ("train", "validation", "heldout")
#: The fraction of measured values within ±2σ of a prediction that counts as calibrated (0.954
#: for Gaussian errors; issue #14's band): below, the band is too narrow, above, too wide.
COVERAGE_BAND = (0.85, 0.99)
#: The default role of consecutive blocks, repeated: 60 % train, 20 % validation, 20 % held out,
#: interleaved so that an effect that starts mid-session (a marker slip) or a region visited only
#: now and then is seen by every role.
DEFAULT_PATTERN = ("train", "train", "validation", "train", "heldout")


@dataclass(frozen=True)
class Blocks:
    """Contiguous blocks of ``n_samples`` samples and their roles.

    Attributes
    ----------
    edges : (K + 1,) int, block k is samples ``edges[k]:edges[k+1]``
    roles : (K,) str, each one of :data:`ROLES`
    """

    edges: np.ndarray
    roles: tuple[str, ...]

    @property
    def n_samples(self) -> int:
        return int(self.edges[-1])

    @property
    def n_blocks(self) -> int:
        return len(self.roles)

    def labels(self) -> np.ndarray:
        """(T,) int, the block of every sample."""
        return np.repeat(np.arange(self.n_blocks), np.diff(self.edges))

    def mask(self, *roles: str) -> np.ndarray:
        """(T,) bool, the samples of blocks with any of ``roles``."""
        bad = [r for r in roles if r not in ROLES]
        if bad:
            raise ValueError(f"unknown block role(s) {bad}; expected {ROLES}")
        keep = np.array([r in roles for r in self.roles], dtype=bool)
        return keep[self.labels()]

    def index(self, *roles: str) -> np.ndarray:
        """Sample indices of the blocks with any of ``roles``, in time order."""
        return np.flatnonzero(self.mask(*roles))

    def to_dict(self, time: np.ndarray | None = None) -> dict:
        """``{role: [[start, stop], ...]}`` in samples, or in seconds when ``time`` is given."""
        out = {r: [] for r in ROLES}
        for k, role in enumerate(self.roles):
            a, b = int(self.edges[k]), int(self.edges[k + 1])
            if time is None:
                out[role].append([a, b])
            else:
                out[role].append([float(time[a]), float(time[b - 1])])
        return out


def split_blocks(n_samples: int, n_blocks: int = 10, pattern=DEFAULT_PATTERN) -> Blocks:
    """Cut ``n_samples`` into ``n_blocks`` contiguous blocks of (nearly) equal length with roles
    from ``pattern`` repeated; a log too short for ``n_blocks`` blocks of 2 samples gets fewer."""
    if n_samples < 2:
        raise ValueError(f"cannot split {n_samples} sample(s) into blocks")
    n_blocks = int(max(1, min(n_blocks, n_samples // 2)))
    edges = np.round(np.linspace(0, n_samples, n_blocks + 1)).astype(int)
    roles = tuple(pattern[k % len(pattern)] for k in range(n_blocks))
    return Blocks(edges, roles)


def sub_blocks(mask: np.ndarray, length: int) -> np.ndarray:
    """Cluster labels (T,) for the samples where ``mask`` is True: consecutive runs of the mask cut
    into pieces of about ``length`` samples (a piece never spans a gap in the mask); -1 elsewhere.

    These are the independent units of a block (cluster-robust) variance: pick ``length`` longer
    than the residuals' correlation time.
    """
    mask = np.asarray(mask, bool)
    out = np.full(mask.shape, -1, dtype=int)
    idx = np.flatnonzero(mask)
    if idx.size == 0:
        return out
    length = max(int(length), 1)
    run_start = np.concatenate([[True], np.diff(idx) > 1])
    run = np.cumsum(run_start) - 1
    pos = np.arange(idx.size) - np.flatnonzero(run_start)[run]
    sizes = np.bincount(run)
    n_pieces = np.maximum(np.round(sizes / length).astype(int), 1)
    piece = np.minimum((pos * n_pieces[run]) // sizes[run], n_pieces[run] - 1)
    offsets = np.concatenate([[0], np.cumsum(n_pieces)[:-1]])
    out[idx] = offsets[run] + piece
    return out


@dataclass(frozen=True)
class Score:
    """Held-out (or in-sample) errors of one model on one set of samples, per channel.

    Attributes
    ----------
    channels : (C,) names
    rmse : (C,) root-mean-square error in the channel's unit (markers: of the 3-D distance)
    nmse : (C,) mean squared error / variance of the measurement (thesis §3.4.2)
    mae : (C,) mean absolute error (markers: mean distance, thesis Table 2.2)
    coverage : (C,) fraction of measurements within ±2 predictive std, or None without a std
    n_samples : (C,) samples scored (finite measurements)
    unit : unit of rmse and mae
    """

    channels: tuple[str, ...]
    rmse: np.ndarray
    nmse: np.ndarray
    mae: np.ndarray
    coverage: np.ndarray | None
    n_samples: np.ndarray
    unit: str = ""

    def pooled_rmse(self) -> float:
        """RMSE over every scored sample of every channel."""
        n = self.n_samples.astype(float)
        ok = n > 0
        return float(np.sqrt(np.sum(self.rmse[ok] ** 2 * n[ok]) / max(n[ok].sum(), 1.0)))

    def to_dict(self) -> dict:
        out = {
            "unit": self.unit,
            "rmse": _by_channel(self.channels, self.rmse),
            "nmse": _by_channel(self.channels, self.nmse),
            "mae": _by_channel(self.channels, self.mae),
        }
        if self.coverage is not None:
            out["coverage_2sigma"] = _by_channel(self.channels, self.coverage)
        return out


def score(measured, predicted, channels, std=None, unit: str = "", mask=None) -> Score:
    """Per-channel scores of ``predicted`` against ``measured``.

    Parameters
    ----------
    measured, predicted : (T, C) or, for 3-D points such as markers, (T, C, 3); NaN in
        ``measured`` (an occluded marker) is skipped
    channels : (C,) names
    std : (T, C) predictive std of a measurement, or None (no coverage)
    mask : (T,) bool, the samples to score (e.g. ``blocks.mask("heldout")``), default all
    """
    measured, predicted = np.asarray(measured, float), np.asarray(predicted, float)
    if measured.shape != predicted.shape:
        raise ValueError(f"measured {measured.shape} and predicted {predicted.shape} differ in shape")
    if mask is not None:
        mask = np.asarray(mask, bool)
        measured, predicted = measured[mask], predicted[mask]
        std = None if std is None else np.asarray(std, float)[mask]
    err = predicted - measured
    if err.ndim == 3:  # points: the distance is the error, the spread of all 3 axes the variance
        ok = np.isfinite(measured).all(axis=-1)
        d = np.linalg.norm(np.where(ok[..., None], err, 0.0), axis=-1)
        var = np.array(
            [np.nanvar(measured[ok[:, c], c], axis=0).sum() if ok[:, c].any() else np.nan for c in range(ok.shape[1])]
        )
        sq, ab = d**2, d
    else:
        ok = np.isfinite(measured) & np.isfinite(predicted)
        sq, ab = np.where(ok, err, 0.0) ** 2, np.abs(np.where(ok, err, 0.0))
        var = np.array([np.var(measured[ok[:, c], c]) if ok[:, c].any() else np.nan for c in range(ok.shape[1])])
    n = ok.sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        mse = np.where(n > 0, (sq * ok).sum(axis=0) / n, np.nan)
        mae = np.where(n > 0, (ab * ok).sum(axis=0) / n, np.nan)
        nmse = mse / np.where(var > 0, var, np.nan)
    coverage = None
    if std is not None:
        inside = (np.abs(err) <= 2.0 * np.asarray(std, float)) & ok
        coverage = inside.sum(axis=0) / np.maximum(n, 1)
    return Score(tuple(channels), np.sqrt(mse), nmse, mae, coverage, n, unit)


def nmse(pred: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Normalised MSE per column (thesis §3.4.2: normalised by the target's variance)."""
    var = np.var(truth, axis=0)
    return np.mean((pred - truth) ** 2, axis=0) / np.where(var > 0, var, 1.0)


def block_mse(sq_err: np.ndarray, labels: np.ndarray, n_blocks: int | None = None) -> np.ndarray:
    """Mean of ``sq_err`` (T,) or (T, C) per block ``labels`` (T,) (>= 0; -1 is left out):
    (B,) or (B, C); NaN for an empty block."""
    sq_err = np.asarray(sq_err, float)
    keep = labels >= 0
    B = int(labels.max()) + 1 if n_blocks is None else n_blocks
    flat = sq_err.reshape(sq_err.shape[0], -1)[keep]
    lab = labels[keep]
    counts = np.bincount(lab, minlength=B).astype(float)
    sums = np.stack([np.bincount(lab, weights=flat[:, c], minlength=B) for c in range(flat.shape[1])], axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        out = sums / counts[:, None]
    return out.reshape((B,) + sq_err.shape[1:])


def paired_se(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Mean and standard error of the paired per-block difference ``a - b``, blocks on axis 0.

    Returns (mean, se), each of the shape of one block's values.
    """
    d = np.asarray(a, float) - np.asarray(b, float)
    n = d.shape[0]
    return d.mean(axis=0), d.std(axis=0, ddof=1) / np.sqrt(n) if n > 1 else np.full(d.shape[1:], np.inf)


def choose_by_validation(per_block: np.ndarray, fallback: int, min_gain: float = 0.0) -> np.ndarray:
    """Per output, the option of lowest mean held-out error, unless it beats the ``fallback``
    option by at most one standard error of their paired per-block difference, or by at most
    ``min_gain`` times the fallback's mean error: then the fallback (the one-standard-error rule,
    Hastie et al., *Elements of Statistical Learning* §7.10, with the simplest model as the
    fallback). ``per_block`` (options, blocks, outputs); returns option indices (outputs,). Ties
    of the mean go to the earlier option."""
    choice = np.argmin(per_block.mean(axis=1), axis=0)
    for j, c in enumerate(choice):
        gain = per_block[fallback, :, j] - per_block[c, :, j]
        if c != fallback and np.all(np.isfinite(gain)):
            floor = max(gain.std(ddof=1) / np.sqrt(len(gain)), min_gain * per_block[fallback, :, j].mean())
            if gain.mean() <= floor:
                choice[j] = fallback
    return choice


def _by_channel(channels, values) -> dict:
    return {c: (None if not np.isfinite(v) else float(v)) for c, v in zip(channels, values, strict=True)}
