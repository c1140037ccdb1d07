"""A marker that slips on its link (the kinematics diagnosis's ``marker_slip``): where in the log
it may have moved, from prefix sums of each frame's weighted normal equations (O(T)), and its
columns from the change on, made only for the rows the engine reads."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from diegocal.diagnose.spill import Spill
from diegocal.robot.gauges import gauge_axes
from diegocal.stac.terms import SLIP


class FromSample:
    """Columns (T, ...) that are zero before sample ``first``: a slip variant, made only when the
    engine reads it (np.asarray), so that a family of change times shares one array."""

    def __init__(self, base: np.ndarray, first: int):
        self.base, self.first = base, first
        self.shape = base.shape
        self.ndim = base.ndim

    def __array__(self, dtype=None, copy=None):
        out = np.array(self.base, dtype=dtype)
        out[: self.first] = 0.0
        return out

    def __getitem__(self, rows):
        """The rows asked for (the engine reads a fit's or a test's samples), zero before ``first``."""
        out = np.array(self.base[rows])
        out[np.arange(self.shape[0])[rows] < self.first] = 0.0
        return out


def slip_samples(train: np.ndarray, cols: np.ndarray, r: np.ndarray, w: np.ndarray) -> list[int]:
    """Candidate slip samples of a marker: in each run of training frames the change time that
    fits best, and the first, middle and last frame of each gap between runs (none in the first and
    last 5 % of the log): the training frames cannot tell them apart, so all three are tested on
    the validation frames, which may hold the slip's start (a slip at a training block's end);
    where they cannot tell them apart either (a gap that is a held-out block), the middle, listed
    first, halves the worst error.

    The scan fits the marker's (projected) position columns ``cols`` (T, R, 3) to the residual rows
    ``r`` (T, R) with weights ``w`` (T, R) (zero off the training frames) separately before and
    after each change time k; the best k maximises the sum of the two fits' weighted gains
    bᵀ G⁻¹ b, from prefix sums of the per-frame G = Cᵀ W C and b = Cᵀ W r (O(T)). A change at a
    run's first frame is a change in the gap before it: the gap's three frames stand for it."""
    Cw = cols * w[..., None]
    return change_times(train, np.einsum("trk,trl->tkl", Cw, cols), np.einsum("trk,tr->tk", Cw, r))


def change_times(train: np.ndarray, G: np.ndarray, b: np.ndarray) -> list[int]:
    """:func:`slip_samples` from each frame's G (T, 3, 3) and b (T, 3), or from the training frames'
    alone (G (T_train, 3, 3), b (T_train, 3)): the others' are zero, so the prefix sums at the
    training frames, all the scan reads, are the same either way (to the bit: adding 0 is exact)."""
    T = train.size
    if not len(G):  # no training frame: no run to scan, no gap between runs
        return []
    at = np.flatnonzero(train) if G.shape[0] < T else np.arange(T)  # row of G of each scanned frame
    row = np.zeros(T, int)
    row[at] = np.arange(len(at))
    G, b = np.cumsum(G, axis=0), np.cumsum(b, axis=0)  # Σ over frames ≤ t
    fit = gain(G, b) + gain(G[-1] - G, b[-1] - b)  # change after each row's frame
    edges = np.flatnonzero(np.diff(np.concatenate([[0], train.astype(int), [0]])))
    runs = list(zip(edges[0::2], edges[1::2], strict=True))
    out = []
    for i, (a, e) in enumerate(runs):
        if e - a > 2:  # a change after the run's first frame and before its last
            out.append(int(a + 1 + np.argmax(fit[row[a] : row[e - 2] + 1])))
        if i + 1 < len(runs):  # the gap's middle, first and last frame: the same training fit
            out += [int((e + runs[i + 1][0]) // 2), int(e), int(runs[i + 1][0] - 1)]
    lo, hi = int(0.05 * T), int(0.95 * T)
    return list(dict.fromkeys(k for k in out if lo <= k <= hi))  # in time; a gap's middle first


class SlipScan:
    """Each training frame's G and b of :func:`slip_samples` for the markers ``names``, gathered from
    the projected position columns a :class:`Sweep` hands :meth:`add` (column sets ``first`` on):
    (T_train, 3, 3) and (T_train, 3) per marker, not the (T, R, 3) columns, nor the other frames'
    (zero: issue #33, 2.3 kB a frame on diego), in a temporary file (:class:`~.spill.Spill`) as they
    come: :meth:`samples` reads one marker's back at a time."""

    def __init__(self, train: np.ndarray, names, first: int):
        self.first = first
        self.row = np.cumsum(train) - 1  # each training frame's row
        n = int(np.count_nonzero(train))
        spill = Spill()
        self.G = [spill.zeros((n, 3, 3)) for _ in names]
        self.b = [spill.zeros((n, 3)) for _ in names]
        self._r: tuple | None = None  # (block start, its residual rows and training weights)

    def add(self, lin, i: int, cols: np.ndarray) -> None:
        if i < self.first or not lin.train.any():  # G and b are sums over training frames only
            return
        if self._r is None or self._r[0] != lin.start:
            r = lin.residual_rows()
            ok = np.isfinite(r)
            self._r = (lin.start, np.where(ok, r, 0.0), np.where(ok, lin.w, 0.0) * lin.train[:, None])
        _, r, w = self._r
        k = np.flatnonzero(lin.train)
        Cw = cols[k] * w[k, :, None]
        Cw = np.swapaxes(Cw, 1, 2)  # (T, 3, R): per-frame products by matmul, not einsum (ten times faster)
        at = int(self.row[lin.start + k[0]])  # the block's training frames: consecutive rows from here
        self.G[i - self.first].write(at, Cw @ cols[k])
        self.b[i - self.first].write(at, (Cw @ r[k, :, None])[..., 0])

    def samples(self, m: int, train: np.ndarray) -> list[int]:
        return change_times(train, np.asarray(self.G[m]), np.asarray(self.b[m]))

def gain(G: np.ndarray, b: np.ndarray) -> np.ndarray:
    """bᵀ G⁺ b (K,) for stacks G (K, 3, 3), b (K, 3): the weighted sum of squares a least-squares
    fit of those columns removes."""
    return np.einsum("ki,ki->k", b, np.einsum("kij,kj->ki", np.linalg.pinv(G, hermitian=True), b))


def slip_value(term, cal, robot):
    """A slip's value: the fitted position of its second marker minus the first's (``cal``'s), with
    ``extra.gauge`` (:func:`slip_gauge`) when the marker is placed in a leaf gauge of ``robot``."""
    if term.cause != "marker_slip":
        return term
    i, k = cal.marker_names.index(term.channel), cal.marker_names.index(term.channel + SLIP)
    d = cal.marker_xyz[k] - cal.marker_xyz[i]
    cov = move_covariance(cal, i, k)
    term = term.with_values(d, [stderr(cov, e) for e in np.eye(3)])
    bound = gauge_axes(robot, [g["joint"] for g in cal.gauges if g.get("kind") == "leaf"])
    if term.channel not in bound:  # (an earlier fit's gauge, if any, no longer holds)
        return replace(term, extra={k: v for k, v in term.extra.items() if k != "gauge"})
    return replace(term, extra=term.extra | {"gauge": slip_gauge(*bound[term.channel], d, cov)})


def move_covariance(cal, i: int, k: int) -> np.ndarray:
    """(2, 3, 3) covariance of marker k's position minus marker i's, reported and model-based:
    both blocks less their cross blocks (the two are fitted from disjoint frames but share the
    calibration and the link's pose errors, which the difference cancels); without
    ``marker_xyz_cov``, their standard errors taken as independent."""
    if cal.marker_xyz_cov is None:
        se = cal.marker_xyz_se if cal.marker_xyz_se is not None else np.full(cal.marker_xyz.shape, np.nan)
        return np.stack([np.diag(se[k] ** 2 + se[i] ** 2)] * 2)
    c = cal.marker_xyz_cov
    a, b = slice(3 * i, 3 * i + 3), slice(3 * k, 3 * k + 3)
    return c[:, b, b] + c[:, a, a] - c[:, b, a] - c[:, a, b]


def stderr(cov: np.ndarray, v: np.ndarray) -> float:
    """The standard error of v·x for ``cov`` (2, 3, 3) of x: the larger of the reported and the
    model-based (as STAC floors each parameter's)."""
    return float(np.sqrt(max(v @ cov[0] @ v, v @ cov[1] @ v)))


def slip_gauge(joint: str, axis: np.ndarray, d: np.ndarray, cov: np.ndarray) -> dict:
    """What the data fix of a slip ``d`` (3,), covariance ``cov`` (2, 3, 3) (:func:`stderr`), whose
    direction about ``joint``'s axis (a unit vector in the marker's link frame) is the fit's gauge:
    its length and its component along the axis, each with its standard error to first order."""
    length = float(np.linalg.norm(d))
    u = d / length if length > 0 else np.full(3, np.nan)
    return {
        "joint": joint,
        "axis": [round(float(a), 6) for a in axis],
        "length": {"value": length, "stderr": stderr(cov, u), "unit": "m"},
        "along_axis": {"value": float(axis @ d), "stderr": stderr(cov, axis), "unit": "m"},
    }
