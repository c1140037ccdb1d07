"""The kinematics diagnosis's columns a block of frames at a time (issue #33: long logs): a
:class:`Sweep` makes many terms' columns from the linearisation at a fit
(:class:`~diegocal.diagnose.kinematics_lin.Linearised`) in three passes over blocks of
SWEEP_FRAMES frames (the calibration-fit sums, on the blocks with training frames only; the checks
on the cleaned columns; the kept channels written in float32), so that the whole log's Jacobians
and inverse normal matrices are never held: only sums of size k×k or k0×k outlive a block.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from diegocal.diagnose.kinematics_lin import (
    CHANNEL_SHARE,
    COLUMN_DTYPE,
    PROJECT_COLUMNS,
    SWEEP_FRAMES,
    Linearised,
    identifying,
    marker_moves,
    row_gram,
    weighted_gram,
)
from diegocal.diagnose.spill import BlockStore, DiskArray, Spill, on_disk
from diegocal.parallel import in_order
from diegocal.progress import ticker
from diegocal.stac.loo import batch_projection, frame_slices, pot_sigmas, sigma_of
from diegocal.stac.model import Observation

#: What a column is fitted out of on the training frames (:class:`Columns`): the calibration's span.
CALIBRATION = "calibration"


@dataclass(frozen=True)
class Columns:
    """How a :class:`Sweep` makes a term's columns: ``make(lin)`` gives them (B, R, k) on a block
    ``lin`` (:class:`Linearised`), which the sweep projects (:meth:`Linearised.project`) unless
    ``projected``; ``span`` is what is fitted out of them on the training
    frames: CALIBRATION (:meth:`Linearised.beyond_calibration`), a pot's index (the gains and biases
    of the pots that read its joints, :meth:`Sweep.sharing`: a pot term's columns lie on its own row
    before projection and on its joints' q directions after it; the other calibration directions
    are orthogonal to them up to what the q projection spreads), or None (nothing, and no
    identifiability test: a slipped marker's re-fit position)."""

    make: Callable
    span: object = CALIBRATION
    projected: bool = False

    def __post_init__(self):
        if self.projected and self.span == CALIBRATION:  # its fit is taken out before the projection
            raise ValueError("columns made projected are fitted out of a pot's span, not the calibration's")


class Sweep:
    """The linearisation at a fit (:class:`Linearised`), a block of frames at a time (module
    docstring): the columns of many terms in one sweep of three passes (:meth:`channels`,
    :meth:`design`). ``train_only``: only the blocks that hold training frames, all that a
    Gauss-Newton step's :meth:`design` reads (every sum it takes is over the training frames); not
    for :meth:`channels`, which writes every frame's columns."""

    def __init__(self, fitted, adapter, train_only: bool = False):
        a = fitted.applied
        self.fitted, self.adapter = fitted, adapter
        self.obs = Observation(a.log, a.robot, need=(), needed_by="diagnose")
        self.params = self.obs.params_from(fitted.cal)
        self.sigma = sigma_of(fitted.cal)
        self.sigma_p = pot_sigmas(self.obs, self.sigma)  # the pots' σ as weighed (P,)
        self.T, self.P = fitted.q.shape[0], self.obs.n_pots
        self.R = self.P + 3 * self.obs.n_markers
        slices = frame_slices(self.T, SWEEP_FRAMES)
        self.train_only = train_only
        self.trained = [sl for sl in slices if fitted.train[sl].any()]  # the blocks a fit's sums read
        self.slices = self.trained if train_only else slices
        self._cal_pinv: np.ndarray | None = None
        self._pot_gram: np.ndarray | None = None  # (2P, 2P) of every pot's projected gain and bias
        self._pot_pinv: dict = {}
        self.jobs = adapter.options.jobs  # threads making blocks (:meth:`_each`)
        self.progress = getattr(adapter, "progress", None)  # told how far the three passes are
        self._tick = lambda: None
        self._sharing: dict = {}
        # each block's linearisation as made on the first pass over it: the next passes read it
        # back (a few milliseconds) instead of making it again (the forward kinematics, the
        # Jacobians and an n x n inverse per frame: a sixth of a pass)
        self.kept = BlockStore(self.T)
        self._scratch: Spill | None = None  # :meth:`on_disk`'s file

    def on_disk(self, x: np.ndarray) -> DiskArray:
        """``x`` (T, ...) in the sweep's scratch file, which its blocks read a block of rows at a time:
        a round's pot candidates' whole-log ∂p̂/∂θ (2.4 kB a frame on diego) are not held (issue #33)."""
        if self._scratch is None:
            self._scratch = Spill()
        return on_disk(x, spill=self._scratch)[0]

    def blocks(self):
        """Each block's :class:`Linearised`, in turn."""
        for sl in self.slices:
            yield self._block(sl)  # the caller's block is the only one alive while the next is made

    def _block(self, sl: slice) -> Linearised:
        """The :class:`Linearised` of the frames ``sl``, made on the first pass that reads it and
        read back from :attr:`kept` on the others."""
        got = self.kept.get(sl)
        if got is None:
            f = batch_projection(self.obs, self.params, self.sigma, self.fitted.q, sl, solve=False)
            # (JᵀWJ + D)⁻¹, as frame_projection's K solves with it
            got = {"J": f.J, "Hi": np.linalg.inv(f.H), "w": f.w, "s": f.s, "Rl": f.Rl, "D": f.D}
            self.kept.put(sl, got)
        return Linearised(self.adapter, self.fitted, self.obs, self.params, sigma_p=self.sigma_p, start=sl.start, **got)

    def mapped_index(self, name: str) -> int:
        return self.obs.marker_names.index(name)

    def marker_sources(self, name: str) -> tuple[int, list]:
        """A log marker channel's mapped marker and its slips' [(second mapped marker, first
        frame)], in order: from each slip on, the channel is read as its second marker."""
        names = self.obs.marker_names
        slips = self.fitted.applied.slips.items()
        return names.index(name), [(names.index(v), first) for v, (o, first) in slips if o == name]

    def observed_joints(self) -> list[str]:
        robot = self.adapter.robot
        return [j for j in robot.joint_names if np.any(marker_moves(self.obs, robot, j) != 0)]

    def sharing(self, j: int) -> list[int]:
        """Pots (mapped order) that read a joint pot j reads (j first)."""
        if j not in self._sharing:
            A = self.obs.A != 0
            if self.obs.kinds[j] == "linear" or not A[j].any():
                self._sharing[j] = [j]
            else:
                kin = self.obs.kinds
                others = [i for i in range(self.P) if i != j and kin[i] != "linear" and np.any(A[i] & A[j])]
                self._sharing[j] = [j, *others]
        return self._sharing[j]

    # ------------------------------------------------------------------ the three passes
    def _passes(self, n: int) -> None:
        """Progress over the next ``n`` passes, with the time left (a long log's take minutes)."""
        blocks = len(self.trained) + (n - 1) * len(self.slices)  # the first pass: the fit's sums
        what = f"candidate columns, {n} passes over blocks of {SWEEP_FRAMES} frames"
        self._tick = ticker(self.progress, blocks, what)

    def _each(self, cols: list[Columns], betas, maps, see, block=None, slices=None) -> None:
        """For each block (``block(lin)`` first, when given) and each of ``cols`` in turn: its
        projected columns on the block with their fit ``betas`` taken out and ``maps`` applied
        (None: not), handed to ``see(lin, [(i, columns), ...])`` a group of sets at a time, in
        order. The columns of several sets are projected together, PROJECT_COLUMNS at a time: one
        product with each frame's J for all of them (six times cheaper per column than one at a
        time). With ``jobs`` > 1 the next blocks' columns are made in threads while ``see`` reads
        this one's (:func:`~diegocal.parallel.in_order`: the same calls in the same order).
        ``slices``: the blocks (default: the sweep's)."""
        if not cols and block is None:
            return

        def producer(sl):
            def made():
                lin = self._block(sl)
                if block is not None:
                    yield lin, None
                pending, width = [], 0
                for i, c in enumerate(cols):
                    C = c.make(lin)
                    pending.append((i, C))
                    width += C.shape[-1]
                    if width >= PROJECT_COLUMNS or i == len(cols) - 1:
                        yield lin, self._items(lin, cols, pending, betas, maps)
                        pending, width = [], 0

            return made

        last = len(cols) - 1
        for lin, items in in_order([producer(sl) for sl in (self.slices if slices is None else slices)], self.jobs):
            if items is None:
                block(lin)
            else:
                see(lin, items)
            if last < 0 if items is None else items[-1][0] == last:  # the block's last call
                self._tick()
            del lin, items  # before the next block is made

    def _items(self, lin: Linearised, cols, pending, betas, maps) -> list:
        """:meth:`_each`'s [(index, columns)] for the sets ``pending`` [(index, columns as made)]
        of one block."""
        made = dict(pending)
        raw = [i for i, _ in pending if not cols[i].projected]
        if raw:  # one projection for every raw set, its fit taken out first: S C − S F β = S (C − F β)
            C = np.concatenate([made[i] for i in raw], axis=-1)
            at = np.cumsum([0] + [made[i].shape[-1] for i in raw])
            cal = [n for n, i in enumerate(raw) if betas[i] is not None and cols[i].span == CALIBRATION]
            if cal:  # F β of every set at once (the makers' columns are finite)
                beta = np.zeros((betas[raw[cal[0]]].shape[0], C.shape[-1]))
                for n in cal:
                    beta[:, at[n] : at[n + 1]] = betas[raw[n]]
                C -= lin._calibration_apply(beta)
            done = _finite(lin.project(C))
            made.update(zip(raw, _split(done, [made[i] for i in raw]), strict=True))
        made.update((i, _finite(made[i])) for i, _ in pending if cols[i].projected)
        items = []
        for i, _ in pending:
            C = made.pop(i)
            if betas[i] is not None and cols[i].span != CALIBRATION:
                C = C - lin.pot_span(self.sharing(cols[i].span)) @ betas[i]
            items.append((i, C if maps is None or maps[i] is None else C @ maps[i]))
        return items

    def _fits(self, cols: list[Columns]) -> tuple[list, list, list]:
        """Pass 1, over the blocks that hold training frames: each column set's fit by its span on
        the training frames (β (k_span, k)), the Gram matrix of its columns there (k, k) and their
        products with the span (b, (k_span, k): β = G⁺ b, G the span's Gram matrix); the
        calibration's and the pots' Gram matrices (sums over the blocks) on the first sweep that
        needs them."""
        n = len(cols)
        b, raw = [None] * n, [None] * n
        need_cal = self._cal_pinv is None and any(c.span == CALIBRATION for c in cols)
        need_pot = self._pot_gram is None and any(c.span not in (None, CALIBRATION) for c in cols)
        k0 = 2 * self.P + 3 * self.obs.n_markers + 6
        G = np.zeros((k0, k0)) if need_cal else None
        Gp = np.zeros((2 * self.P, 2 * self.P)) if need_pot else None

        def block(lin):
            nonlocal G, Gp
            if need_cal:
                G += lin._gram_part()
            if need_pot:
                Gp += lin.pot_gram()

        def add(lin, items):
            wt = lin.w * lin.train[:, None]
            cal = [(i, C) for i, C in items if cols[i].span == CALIBRATION]
            dots = {}
            if cal:  # (S F)ᵀ W C = Fᵀ W C, as S C = C: every set's at once
                both = lin._calibration_dot(wt[..., None] * np.concatenate([C for _, C in cal], axis=-1))
                dots = dict(zip([i for i, _ in cal], _split(both, [C for _, C in cal]), strict=True))
            for i, C in items:
                if i in dots:
                    bi = dots[i]
                else:
                    N = lin.pot_span(self.sharing(cols[i].span))
                    bi = (N * wt[..., None]).reshape(-1, N.shape[-1]).T @ C.reshape(-1, C.shape[-1])
                gi = weighted_gram(C, wt)
                b[i], raw[i] = (bi, gi) if b[i] is None else (b[i] + bi, raw[i] + gi)

        fitted = [i for i, c in enumerate(cols) if c.span is not None]
        self._each(
            [cols[i] for i in fitted],
            [None] * len(fitted),
            None,
            lambda lin, items: add(lin, [(fitted[j], C) for j, C in items]),
            block,
            self.trained,
        )
        if need_cal:
            self._cal_pinv = np.linalg.pinv(0.5 * (G + G.T), rcond=1e-10, hermitian=True)
        if need_pot:
            self._pot_gram = Gp
        betas = [None if b[i] is None else self._span_pinv(c.span) @ b[i] for i, c in enumerate(cols)]
        return betas, raw, b

    def _span_pinv(self, span) -> np.ndarray:
        if span == CALIBRATION:
            return self._cal_pinv
        if span not in self._pot_pinv:
            idx = [x for i in self.sharing(span) for x in (2 * i, 2 * i + 1)]
            self._pot_pinv[span] = np.linalg.pinv(self._pot_gram[np.ix_(idx, idx)], rcond=1e-10, hermitian=True)
        return self._pot_pinv[span]

    def _maps(self, cols: list[Columns], betas, raw, see=None, families=None) -> tuple[list, list]:
        """Pass 2: each column set's map onto its identifiable directions (None: all are, or no
        test) and its weighted energy per mapped row (R,) over every frame; None for a set that is
        zero everywhere. ``see(lin, i, columns)`` also reads each set's columns (no map applied),
        and ``families`` (:class:`~diegocal.diagnose.kinematics_families.FamilyRanks`) those it ranks."""
        n = len(cols)
        kept = [np.zeros((c.shape[0], c.shape[0])) if c is not None else None for c in raw]
        rows: list = [None] * n
        nonzero = [False] * n

        def add(lin, items):
            root = np.sqrt(lin.w)
            train = lin.train
            wt = lin.w * train[:, None] if train.any() else None  # None: no training frame, no sum on them
            for i, C in items:
                rg = row_gram(C, root)
                rows[i] = rg if rows[i] is None else rows[i] + rg
                nonzero[i] = nonzero[i] or bool(np.any(C))
                if kept[i] is not None and wt is not None:
                    kept[i] += weighted_gram(C, wt)
                if see is not None:
                    see(lin, i, C)
                if families is not None and families.ranked(i) and wt is not None:
                    families.add(lin, i, C)

        self._each(cols, betas, None, add)
        maps = [None if kept[i] is None else identifying(kept[i], raw[i]) for i in range(n)]
        energy = []
        for i in range(n):
            M = maps[i]
            if not nonzero[i] or (M is not None and not M.any()):
                energy.append(None)
                continue
            e = np.einsum("rkk->r", rows[i]) if M is None else np.einsum("kl,rlm,mk->r", M, rows[i], M)
            energy.append(e)
        return maps, energy

    def channels(self, cols: list[Columns], see=None, families=None) -> list[dict | None]:
        """Each column set as the engine reads a candidate's: {channel: (T, k) pot or (T, 3, k)
        marker} on the log's channels (slips merged back), in COLUMN_DTYPE on disk
        (:class:`~diegocal.diagnose.spill.DiskArray`), the channels with less
        than CHANNEL_SHARE of its largest channel's weighted energy left out; None for a set that
        is zero everywhere (the calibration takes the term up entirely) and for a family's variant
        that ``families`` ranks below the best (never written). ``see``: :meth:`_maps`."""
        if self.train_only:
            raise ValueError("a sweep of the training blocks only cannot write every frame's columns")
        self._passes(3)
        betas, raw, _ = self._fits(cols)
        maps, energy = self._maps(cols, betas, raw, see, families)
        P, T = self.P, self.T
        out, where = [], []  # where: per set, (channel, mapped rows, [(slip rows, first frame)])
        for i in range(len(cols)):
            if energy[i] is None:
                out.append(None)
                where.append(())
                continue
            e = np.concatenate([energy[i][:P], energy[i][P:].reshape(-1, 3).sum(axis=1)])
            keep = (e >= CHANNEL_SHARE * e.max()) & (e > 0)
            at = [(name, slice(p, p + 1), ()) for p, name in enumerate(self.obs.pot_names) if keep[p]]
            for name in self.adapter.marker_names:
                j, second = self.marker_sources(name)
                if any(keep[P + x] for x in [j, *[v for v, _ in second]]):
                    at.append((name, _rows(P, j), [(_rows(P, v), first) for v, first in second]))
            out.append({})
            where.append(at)
        if families is not None:
            rows = {i: _mapped_rows(at) for i, at in enumerate(where)}
            for i in families.dropped(rows, maps):
                out[i], where[i] = None, ()

        live = [i for i in range(len(cols)) if where[i]]
        spill = Spill()  # the round's columns on disk: a long log's would not fit in memory

        def write(lin, items):
            for n, C in items:
                _write(out[live[n]], where[live[n]], lin.frames, C, T, spill)

        self._each([cols[i] for i in live], [betas[i] for i in live], [maps[i] for i in live], write)
        return out

    def design(self, cols: list[Columns], see) -> None:
        """The columns of every set side by side on each block (B, R, Σk), fitted out and mapped as
        :meth:`channels` would keep them, handed to ``see(lin, columns)`` (a Gauss-Newton step's
        normal equations, a block at a time). Two passes: the Gram matrix of the columns with their
        fit β = G⁺ b taken out, which :meth:`_maps` sums in a pass of its own, is raw − bᵀ G⁺ b
        (G⁺ G G⁺ = G⁺), all on the training frames; its cancellation turns the kept directions by
        about 1e-8, far below a step's tolerance."""
        self._passes(2)
        betas, raw, b = self._fits(cols)
        maps = [None if g is None else identifying(g - bi.T @ be, g) for g, bi, be in zip(raw, b, betas, strict=True)]
        held: list = []

        def gather(lin, items):
            held.extend(C for _, C in items)
            if items[-1][0] == len(cols) - 1:
                see(lin, np.concatenate(held, axis=-1))
                held.clear()

        self._each(cols, betas, maps, gather)


def _write(out: dict, where, sl: slice, C: np.ndarray, T: int, spill: Spill) -> None:
    """A set's columns C (B, R, k) on the frames ``sl`` into its kept channels ``out`` (channel ->
    (T, k) or (T, 3, k) in ``spill``'s file, made on the first block), ``where``: (channel, its
    mapped rows, [(a slip's rows, its first frame)]): a slipped marker's columns from its slip on
    are its second marker's."""
    for name, rows, second in where:
        x = C[:, rows]
        block = np.array(x[:, 0] if x.shape[1] == 1 else x, COLUMN_DTYPE)
        for srows, first in second:
            a = max(first - sl.start, 0)
            block[a:] = C[a:, srows]
        if name not in out:
            out[name] = spill.array((T, *block.shape[1:]), COLUMN_DTYPE)
        out[name].write(sl.start, block)


def _mapped_rows(where) -> np.ndarray:
    """The mapped rows of a set's kept channels (:meth:`Sweep.channels`' ``where``)."""
    spans = [r for _, rows, second in where for r in (rows, *(s for s, _ in second))]
    return np.concatenate([np.arange(s.start, s.stop) for s in spans]) if spans else np.zeros(0, int)


def _finite(C: np.ndarray) -> np.ndarray:
    """C with NaN set to 0 (in place: a sweep's own arrays), at the cost of one check where none is."""
    return C if np.isfinite(C).all() else np.nan_to_num(C, copy=False)


def _split(C: np.ndarray, like: list) -> list:
    """Columns (..., Σk) side by side -> the sets of ``like``'s widths."""
    return np.split(C, np.cumsum([x.shape[-1] for x in like])[:-1], axis=-1)


def _rows(P: int, m: int) -> slice:
    """Mapped marker m's three rows."""
    return slice(P + 3 * m, P + 3 * m + 3)


def whole_log(fitted, adapter) -> Linearised:
    """The linearisation of every frame of the log at once (what a :class:`Sweep` holds a block at
    a time): for tests that compare the block-by-block routes with the whole-log ones."""
    sweep = Sweep(fitted, adapter)
    parts = list(sweep.blocks())
    whole = {k: np.concatenate([getattr(p, k) for p in parts]) for k in ("J", "Hi", "w", "s", "Rl", "D")}
    return Linearised(adapter, fitted, sweep.obs, sweep.params, sigma_p=parts[0].sigma_p, **whole)
