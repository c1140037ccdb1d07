"""Which variant of each kinematic family a :class:`~diegocal.diagnose.kinematics_sweep.Sweep`
writes (issue #33: long logs). The selection tests one variant per family, its best fit on the
training rows (:func:`~diegocal.diagnose.selection.evaluate_candidates`); a backlash's six band
widths and a clock shift's nineteen shifts were half of a round's columns, held for every frame
only to be dropped there. :class:`FamilyRanks` ranks the variants from sums made in the sweep's
second pass, as :class:`~diegocal.diagnose.dynamics_system.FamilyRanks` does for the dynamics.
"""

from __future__ import annotations

import numpy as np

from diegocal.diagnose.kinematics_lin import row_gram


class FamilyRanks:
    """The training fit of each family variant's cleaned columns, from sums over the blocks.

    The sums are the selection's own least squares (:class:`~diegocal.diagnose.selection._Stack`):
    each channel's rows weighted by ``weights`` (1 / its baseline training RMS), on the training
    frames, where the residual is finite and not written off (``exclude``), a slipped marker's rows
    its second marker's from the slip on (as :meth:`Sweep.channels` writes them). They are kept per
    mapped row, so that the channels a set keeps (known after the pass) pick theirs. The selection
    fits the columns rounded to float32; these sums are of float64 ones: variants within TIE of the
    best (relative to the family's weighted training energy) are all written, and the selection
    decides between them.
    """

    #: Gains closer than this fraction of Σ w² r² (the channels a variant keeps) are ties.
    TIE = 1e-6

    def __init__(self, sweep, names: list, residuals, weights: dict, exclude: dict, train: np.ndarray):
        self.sweep, self.names = sweep, list(names)
        self.res, self.weights, self.exclude = residuals, weights, exclude or {}
        self.train = np.asarray(train, bool)
        R = sweep.R
        self.g: dict = {}  # set -> (R, k): Σ w² cᵀ r per mapped row
        self.G: dict = {}  # set -> (R, k, k): Σ w² cᵀ c per mapped row
        self.yy = np.zeros(R)  # Σ w² r² per mapped row
        self._block: tuple | None = None  # (start, Y, M) of the block in hand

    def ranked(self, i: int) -> bool:
        return bool(self.names[i])

    def _rows(self, lin) -> tuple[np.ndarray, np.ndarray]:
        """(Y, √M) (B, R) on the block ``lin``: w² r of the channel each mapped row is read as, and
        the root of M, w² where that reading counts (0 elsewhere: not a training frame, missing,
        written off, or a row no channel reads there)."""
        if self._block is not None and self._block[0] == lin.start:
            return self._block[1:]
        sweep, sl = self.sweep, lin.frames
        B, P = lin.T, sweep.P
        Y, M = np.zeros((B, sweep.R)), np.zeros((B, sweep.R))
        tr = self.train[sl]
        for p, name in enumerate(sweep.obs.pot_names):
            self._put(Y, M, name, np.full((B, 1), p), tr, sl)
        for name in sweep.adapter.marker_names:
            j, second = sweep.marker_sources(name)
            src = np.full(B, j)
            for v, first in second:  # in Sweep.channels' order: each later slip writes over the earlier
                src[max(first - sl.start, 0) :] = v
            self._put(Y, M, name, P + 3 * src[:, None] + np.arange(3), tr, sl)
        self.yy += np.einsum("br,br->r", Y, np.divide(Y, M, out=np.zeros_like(Y), where=M > 0))
        self._block = (lin.start, Y, np.sqrt(M))
        return self._block[1:]

    def _put(self, Y, M, name: str, cols: np.ndarray, tr: np.ndarray, sl: slice) -> None:
        """Channel ``name``'s weighted residual into the mapped rows ``cols`` (B, d) of Y and M."""
        r = np.asarray(self.res.channels[name], float)[sl].reshape(cols.shape)
        ok = tr[:, None] & np.isfinite(r)
        if name in self.exclude:
            ex = np.asarray(self.exclude[name], bool)[sl]
            ok &= ~(ex[:, None] if ex.ndim == 1 else ex.reshape(cols.shape))
        w2 = self.weights[name] ** 2
        at = (np.arange(cols.shape[0])[:, None], cols)
        Y[at] = np.where(ok, r * w2, 0.0)
        M[at] = ok * w2

    def add(self, lin, i: int, C: np.ndarray) -> None:
        """Set i's cleaned columns C (B, R, k) on the block ``lin`` (the sweep's second pass)."""
        Y, root = self._rows(lin)
        g = np.einsum("brk,br->rk", C, Y)
        G = row_gram(C, root)
        if i in self.g:
            self.g[i] += g
            self.G[i] += G
        else:
            self.g[i], self.G[i] = g, G

    def gains(self, rows: dict, maps: list) -> dict:
        """{ranked set: (its training gain Σ r² − Σ (r − C b)² at the least-squares b, the
        channels' Σ w² r²)} on the channels it keeps. ``rows``: set -> the mapped rows of those
        channels; ``maps``: per set, its map onto its identifiable directions (None: all are)."""
        out = {}
        for i, r in rows.items():
            if not self.ranked(i) or i not in self.g or not len(r):
                continue
            G, g = self.G[i][r].sum(axis=0), self.g[i][r].sum(axis=0)
            if maps[i] is not None:
                G, g = maps[i].T @ G @ maps[i], maps[i].T @ g
            out[i] = (float(g @ np.linalg.pinv(G, hermitian=True) @ g), float(self.yy[r].sum()))
        return out

    def dropped(self, rows: dict, maps: list) -> set:
        """The ranked sets that are neither their family's best fit nor within TIE of it
        (:meth:`gains`' arguments)."""
        fits: dict = {}  # family -> [(set, gain, energy)]
        for i, (gain, energy) in self.gains(rows, maps).items():
            fits.setdefault(self.names[i], []).append((i, gain, energy))
        out = set()
        for family in fits.values():
            top = max(g for _, g, _ in family)
            tie = self.TIE * max(e for _, _, e in family)
            out |= {i for i, g, _ in family if g < top - tie}
        return out
