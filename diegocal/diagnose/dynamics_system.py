"""The dynamics diagnosis's weighted least squares on the training rows, factored once (issue #33:
long logs), and its candidates' projection a chunk of samples at a time.

:class:`TrainingSystem`: one pass over the training samples keeps, per joint j, the triangular
factor R_j of ``[F_j y_j]`` (F_j the base regressor's rows of joint j, y_j its torque less the
fixed part of the prediction; :class:`~diegocal.lstsq.TallLstsq`), a few (r + 1)² numbers.
The rows of a joint share its weight 1 / σ_j, so the factor of the weighted system of every joint
is the QR of the R_j / σ_j stacked, for any σ, with no pass over the data. A model with extra
term columns C (a position friction, a Stribeck scale: what the shape and region searches of
:mod:`.dynamics_shapes` re-solve at every trial) is solved from it by Frisch-Waugh-Lovell, C
acting on a few joints J only:

.. math:: S = C^T C - Z^T Z,\\quad Z = R_{11}^{-T} F^T C,\\quad
          b = S^{-1} C^T e,\\quad \\mathrm{RSS} = \\mathrm{RSS}_F - (C^T e)^T b

(e the residual of the base fit, ``a = a_F − R11⁻¹ Z b`` the base parameters), which needs F_j
only on the training rows of the joints in J (kept, float64: the regressor of a whole long log
is never held). The weighted least squares' solution and error are those of
:meth:`DynamicsAdapter._solve <diegocal.diagnose.dynamics.DynamicsAdapter._solve>` on the full
columns, to rounding; where the algebra could lose digits (F or S close to singular, a column
not finite) :meth:`weighted_fit` returns None and the caller solves directly.

:func:`feature_chunks` gives a fitted model's columns a chunk of samples at a time (all at once
only for a model with a ``torque_lag``, whose filter runs along the whole log).
"""

from __future__ import annotations

import functools

import numpy as np
from scipy.linalg import solve_triangular

from diegocal.lstsq import TallLstsq
from diegocal.progress import ticker
from diegocal.sgp.model import PREDICT_SAMPLES
from diegocal.sgp.regressor import CHUNK, base_regressor
from diegocal.sgp.terms import BODIES, Motion, is_filter, joints_of, motion_columns, term_columns

#: Samples per chunk where a fitted model's columns are rebuilt beside every candidate's: a quarter of the
#: model's own prediction chunk, as these chunks hold both (a long log's peak memory)
SAMPLES = PREDICT_SAMPLES // 4
#: Below this fraction of a candidate's norm left, its projection's fraction is recomputed from the
#: residual itself (the difference of squared norms keeps about 8 digits of it: enough above)
NEAR_SPAN = 1e-3
#: S's smallest eigenvalue below this fraction of CᵀC's largest diagonal: the terms' columns are
#: close to the base regressor's span, the difference CᵀC − ZᵀZ has lost its digits: solve directly
NEAR_SINGULAR = 1e-8


class TrainingSystem:
    """The weighted training least squares of one adapter's base regressor (module docstring).

    ``fit``: the :class:`~diegocal.diagnose.dynamics.DynamicsAdapter` (its robot, states, torques
    and fixed part ``tau0``); ``train``: (T,) bool, the training samples.
    """

    def __init__(self, fit, train: np.ndarray):
        self.fit = fit
        self.idx = np.flatnonzero(train)
        self.r = fit.base.n_base
        k = len(fit.joints)
        self.R = [TallLstsq(self.r) for _ in range(k)]
        for rows, F in self._chunks(self.idx):
            y = fit.tau[rows] - fit.tau0[rows]
            for j in range(k):
                ok = np.isfinite(y[:, j]) & np.isfinite(F[:, j]).all(axis=1)
                self.R[j].add(F[ok, j], y[ok, j])
        self._rows: dict[int, tuple] = {}  # joint row -> (F_j, y_j, ok) on the training samples

    def _chunks(self, idx):
        f = self.fit
        for i in range(0, idx.size, CHUNK):
            rows = idx[i : i + CHUNK]
            yield rows, base_regressor(f.robot, f.q[rows], f.qd[rows], f.qdd[rows], f.base, f.friction, f.rows)

    def joint_rows(self, joints) -> dict:
        """Joint row -> (F_j (Ttr, r), y_j (Ttr,), finite (Ttr,)) on the training samples, unweighted;
        computed for the joints not yet held in one pass (kept: the joints extra terms act on)."""
        need = [j for j in joints if j not in self._rows]
        if need:
            held = {j: np.empty((self.idx.size, self.r)) for j in need}
            at = 0
            for rows, F in self._chunks(self.idx):
                for j in need:
                    held[j][at : at + rows.size] = F[:, j]
                at += rows.size
            f = self.fit
            for j in need:
                Fj = held.pop(j)
                y = f.tau[self.idx, j] - f.tau0[self.idx, j]
                self._rows[j] = (Fj, y, np.isfinite(y) & np.isfinite(Fj).all(axis=1))
        return {j: self._rows[j] for j in joints}

    def _base(self, sigma) -> tuple:
        """(R11 (r, r), a_F (r,), RSS_F, training rows) of the weighted base fit."""
        ls = TallLstsq(self.r)
        stacked = np.concatenate([R.R / s for R, s in zip(self.R, sigma, strict=True)])
        ls.add(stacked[:, : self.r], stacked[:, self.r])
        ls.rows = sum(R.rows for R in self.R)  # the rank cutoff of the rows the factors stand for
        a, rss = ls.solve()
        return ls.R[: self.r, : self.r], a, rss, ls.rows

    def weighted_fit(self, terms, sigma) -> tuple | None:
        """(w (r + K,): base parameters then the terms' linear parameters, the weighted training
        error Σ ((τ − τ̂) / σ_j)², per joint the unweighted training sum of squares (k,)) of the
        baseline with ``terms`` (no ``torque_lag``); None where it must be solved directly."""
        sigma = np.asarray(sigma, float)
        R11, a, rss, n_rows = self._base(sigma)
        d = np.abs(np.diag(R11))
        if d.size and d.min() <= np.finfo(float).eps * max(n_rows, self.r) * d.max():
            return None  # the base regressor is rank-deficient here: lstsq's minimum-norm solution
        f = self.fit
        terms = [t for t in terms if not is_filter(t)]
        if not terms:
            return a, rss, self._joint_rss(a, {}, np.zeros(0))
        idx = self.idx
        C = term_columns(terms, f.robot, f.q[idx], f.qd[idx], f.qdd[idx])[:, f.rows]  # (Ttr, k, K)
        K = C.shape[2]
        J = [j for j in range(C.shape[1]) if np.any(C[:, j] != 0)]
        G, CC, Cy = np.zeros((self.r, K)), np.zeros((K, K)), np.zeros(K)
        for j, (Fj, y, ok) in self.joint_rows(J).items():
            c = C[ok, j] / sigma[j]
            if not np.isfinite(c).all():
                return None
            G += (Fj[ok] / sigma[j]).T @ c
            CC += c.T @ c
            Cy += c.T @ (y[ok] / sigma[j])
        Ce = Cy - G.T @ a  # Cᵀe: e = y − F a
        Z = solve_triangular(R11, G, trans="T")
        S = CC - Z.T @ Z
        scale = float(np.max(np.diag(CC))) if K else 0.0
        if K == 0 or scale <= 0 or np.linalg.eigvalsh(S).min() <= NEAR_SINGULAR * scale:
            return None
        b = np.linalg.solve(S, Ce)
        w = np.concatenate([a - solve_triangular(R11, Z @ b), b])
        return w, float(rss - Ce @ b), self._joint_rss(w[: self.r], {j: C[:, j] for j in J}, b)

    def _joint_rss(self, a, cols: dict, b) -> np.ndarray:
        """Per joint, Σ (y − F a − C b)² over its finite training rows (unweighted): from R_j
        where no term acts, from the rows held where one does."""
        out = np.empty(len(self.R))
        for j, R in enumerate(self.R):
            if j in cols:
                Fj, y, ok = self._rows[j]
                e = y[ok] - Fj[ok] @ a - cols[j][ok] @ b
                out[j] = float(e @ e)
            else:
                v = np.zeros(self.r + 1)
                v[: len(R.R)] = R.R @ np.append(a, -1.0)
                out[j] = float(v @ v)
        return out

    def counts(self) -> np.ndarray:
        """(k,) finite training rows per joint."""
        return np.array([R.rows for R in self.R])


def feature_chunks(model, fit, samples):
    """(sample indices, the model's columns there (m, k, P)) a chunk of ``samples`` at a time: the
    columns of :meth:`~diegocal.sgp.model.DynamicsModel.features` (a ``torque_lag``'s filter
    applied). A model with a lag filters along the whole log: its columns are built once, whole."""
    samples = np.asarray(samples)
    if any(is_filter(t) for t in model.terms):
        A = model.features(fit.q, fit.qd, fit.qdd, fit.time)
        for i in range(0, samples.size, SAMPLES):
            rows = samples[i : i + SAMPLES]
            yield rows, A[rows]
        return
    for i in range(0, samples.size, SAMPLES):
        rows = samples[i : i + SAMPLES]
        yield rows, model.features(fit.q[rows], fit.qd[rows], fit.qdd[rows], fit.time[rows])


def project(fit, fitted, train, width: dict, slots: list, fill, progress=None, families=None) -> tuple:
    """Every candidate's columns minus their least-squares fit by the fitted model's columns X on
    every joint's training rows, rows weighted as the fit weighs them (1 / σ_joint, so that
    Frisch-Waugh-Lovell is exact): ``c − X pinv(X) c``, with ``pinv(X) = pinv(R) pinv(R)ᵀ Xᵀ``
    from the factor R of the weighted X (``XᵀX = RᵀR``, the same singular values), so that X is
    never held: one pass over the training samples for R and every Xᵀc, one over every sample to
    subtract, a chunk at a time, the candidates' columns built in each (``fill``).

    ``width``: joint row -> the width of its block of candidates' columns; ``slots``: per
    candidate, joint row -> its slice of the block; ``fill``: (sample indices, a bool per candidate
    or None) -> {joint row: (m, width) float64}, the columns of those candidates there
    (:func:`filler`). Returns (joint row -> (T, width), the projected columns
    **in float32**: computed in float64 and rounded once, a relative 6e-8 of each projected value,
    which halves the largest array of a round; the fraction of each candidate's weighted training
    norm left (n,), 0 where it lies in the model's span). ``progress``: callable(str) or None, told
    how far the two passes are, with the time left (a long log's take minutes).

    Third: the slots of the held candidates (all of them, ``slots`` itself, without ``families``).
    ``families`` (:class:`FamilyRanks`): only the variant of each family that the selection would
    keep is projected and held (the best training fit of its projected columns, from sums of the
    first pass); the others' slots are None, the held ones' index the smaller blocks, and the
    blocks are a third as wide as all variants'."""
    T = len(fit.time)
    chunks = -(-int(np.sum(train)) // SAMPLES) + -(-T // SAMPLES)
    tick = ticker(progress, chunks, f"candidate columns projected, chunks of {SAMPLES} samples")
    wt = 1.0 / fitted.sigma
    model = fitted.model
    P = fitted.w.size
    n = len(slots)
    xtc = {r: np.zeros((P, w)) for r, w in width.items()}
    sq = {r: np.zeros(w) for r, w in width.items()}
    ls = TallLstsq(P)
    for rows, A in feature_chunks(model, fit, np.flatnonzero(train)):
        Aw = A * wt[None, :, None]
        ls.add(Aw.reshape(-1, P), np.zeros(Aw.shape[0] * Aw.shape[1]))
        for r, c in fill(rows, None).items():
            if families is not None:
                families.add(r, rows, A[:, r], c)
            c *= wt[r]
            xtc[r] += np.ascontiguousarray(Aw[:, r]).T @ c
            sq[r] += np.einsum("ij,ij->j", c, c)
        tick()
    R = np.zeros((P, P))
    R[: min(len(ls.R), P)] = ls.R[:P, :P]
    Rp = np.linalg.pinv(R)
    beta, norm, explained = [], np.zeros(n), np.zeros(n)
    Beta = {r: np.zeros((P, w)) for r, w in width.items()}
    for i, s in enumerate(slots):
        g = sum(xtc[r][:, sl] for r, sl in s.items()) if s else np.zeros((P, 0))
        b = Rp @ (Rp.T @ g)  # the candidate's fit by X: one β over all its joints' rows
        beta.append(b)
        norm[i] = sum(float(np.sum(sq[r][sl])) for r, sl in s.items())
        explained[i] = float(np.sum(g * b))  # ‖X β‖² = cᵀ X β
        for r, sl in s.items():
            Beta[r][:, sl] = b
    frac = np.sqrt(np.maximum(norm - explained, 0.0) / np.where(norm > 0, norm, 1.0))
    near = [i for i in range(n) if norm[i] > 0 and frac[i] < NEAR_SPAN]
    held = {r: np.arange(w) for r, w in width.items()}  # joint row -> the block's columns held
    kept = slots
    if families is not None:
        kept, held = _compact(families.keep(slots, Beta, near), width)
        width = {r: h.size for r, h in held.items()}
        Beta = {r: Beta[r][:, held[r]] for r in Beta}
    left = np.zeros(n)
    is_train = np.asarray(train, bool)
    B = {r: np.empty((T, w), np.float32) for r, w in width.items()}
    wanted = [s is not None for s in kept]
    for rows, A in feature_chunks(model, fit, np.arange(T)):
        C = fill(rows, wanted)
        tr = is_train[rows]
        if near and tr.any():  # near the span, the difference of norms has lost its digits
            Aw = A[tr] * wt[None, :, None]
            for i in near:
                L = Aw @ beta[i]  # (m, k, kc)
                for r, sl in slots[i].items():
                    L[:, r] -= C[r][tr, sl] * wt[r]
                left[i] += float(np.sum(L * L))
        for r, c in C.items():
            B[r][rows] = c[:, held[r]] - np.ascontiguousarray(A[:, r]) @ Beta[r]
        tick()
    for i in near:
        frac[i] = np.sqrt(left[i] / norm[i])
    frac[norm <= 0] = 0.0
    return B, frac, kept


class FamilyRanks:
    """Which variant of each family :func:`project` holds: the one whose projected columns fit the
    training residual best, the family's only variant that the selection tests (:func:`~diegocal.
    diagnose.selection.evaluate_candidates`: the best training fit per family, each joint's rows
    weighted as there), ranked from sums made in the projection's first pass, so that the others'
    columns are never held for every sample.

    ``residual``: joint row -> (T,) the residual; ``weights``: joint row -> the selection's weight
    of that joint (1 / its baseline training RMS); ``names``: per candidate, its family ("": a
    family of its own). The sums are of the unweighted rows where the residual and every
    candidate's column are finite (the selection drops a row per candidate: the same while the
    columns are finite, as every term's are on finite states). The selection ranks float32 columns
    by their QR, these sums rank float64 ones: variants within TIE of the best (relative to the
    family's weighted training energy; two springs whose difference is a constant in the model's
    span tie exactly) are all held, and the selection decides between them.
    """

    #: Gains closer than this fraction of Σ w² r² (the family's joints, training rows) are ties.
    TIE = 1e-9

    def __init__(self, residual: dict, weights: dict, names: list):
        self.residual, self.weights, self.names = residual, weights, list(names)
        self.sums: dict = {}  # joint row -> [AᵀA, AᵀC, CᵀC, Cᵀy, Aᵀy, yᵀy]

    def add(self, r: int, rows, A: np.ndarray, C: np.ndarray) -> None:
        """A chunk of training samples ``rows``: joint row r's model columns A (m, P), the
        candidates' columns C (m, width), both unweighted."""
        y = self.residual[r][rows]
        ok = np.isfinite(y) & np.isfinite(C).all(axis=1)
        A, C, y = np.ascontiguousarray(A[ok]), C[ok], y[ok]
        parts = (A.T @ A, A.T @ C, C.T @ C, C.T @ y, A.T @ y, np.array(y @ y))
        if r not in self.sums:
            self.sums[r] = list(parts)
        else:
            for acc, x in zip(self.sums[r], parts, strict=True):
                acc += x

    def gain(self, slot: dict, Beta: dict) -> tuple[float, float]:
        """(Σ r² − Σ (r − C b)² at the least-squares b, Σ r²), C the projected columns ``c − A β``
        of one candidate (its slice of each joint's block), each joint weighted."""
        k = next(iter(slot.values())).stop - next(iter(slot.values())).start
        G, g, energy = np.zeros((k, k)), np.zeros(k), 0.0
        for r, sl in slot.items():
            if r not in self.sums:
                continue
            AA, AC, CC, Cy, Ay, yy = self.sums[r]
            beta = Beta[r][:, sl]
            cross = beta.T @ AC[:, sl]
            w2 = self.weights[r] ** 2
            G += w2 * (CC[sl, sl] - cross - cross.T + beta.T @ AA @ beta)
            g += w2 * (Cy[sl] - beta.T @ Ay)
            energy += w2 * float(yy)
        return float(g @ np.linalg.pinv(G) @ g), energy

    def keep(self, slots: list, Beta: dict, near) -> list:
        """``slots`` with None for every variant that is not its family's best nor within TIE of
        it; a candidate near the model's span is kept (its sums have lost their digits)."""
        gains: dict = {}  # family -> [(candidate, gain, energy)]
        for i, slot in enumerate(slots):
            if slot and i not in near and self.names[i]:
                gains.setdefault(self.names[i], []).append((i, *self.gain(slot, Beta)))
        chosen = set()
        for family in gains.values():
            top = max(g for _, g, _ in family)
            tie = self.TIE * max(e for _, _, e in family)
            chosen |= {i for i, g, _ in family if g >= top - tie}
        return [s if (not self.names[i] or i in near or i in chosen) else None for i, s in enumerate(slots)]


def _compact(kept: list, width: dict) -> tuple[list, dict]:
    """The kept candidates' slots in blocks of their columns only (None stays None), and per joint
    row the indices of those columns in the full block."""
    held: dict = {r: [] for r in width}
    out = []
    for slot in kept:
        if slot is None:
            out.append(None)
            continue
        new = {}
        for r, sl in slot.items():
            start = len(held[r])
            held[r].extend(range(sl.start, sl.stop))
            new[r] = slice(start, len(held[r]))
        out.append(new)
    return out, {r: np.array(h, int) for r, h in held.items()}


def layout(adapter, props) -> tuple[dict, list]:
    """Where the proposals' columns go side by side per joint of ``adapter`` (a DynamicsAdapter):
    joint row -> the width of its block, and per proposal, joint row -> its slice of the block (a
    payload loads every joint)."""
    slots, width = [], {}
    for p in props:
        if p.columns is not None:
            size = {adapter.row_of[j]: int(np.shape(c)[1]) for j, c in p.columns.items()}
        else:
            joints = adapter.joints if p.term.cause in BODIES else joints_of(p.term)
            size = {adapter.row_of[j]: len(p.term.linear) for j in joints if j in adapter.row_of}
        slot = {}
        for r, kc in size.items():
            slot[r] = slice(width.get(r, 0), width.get(r, 0) + kc)
            width[r] = slot[r].stop
        slots.append(slot)
    return width, slots


def filler(adapter, props, width: dict, slots: list):
    """A function (rows (sample indices), keep) -> {joint row: (m, width) float64}: the proposals'
    columns on those samples, a term's own computed there (its columns are per sample); ``keep``
    (a bool per proposal, or None: all): the others' columns are left unwritten (never read)."""
    both = list(enumerate(zip(props, slots, strict=True)))
    given = [(i, p.columns, slot) for i, (p, slot) in both if p.columns is not None]
    own = [(i, p.term, slot) for i, (p, slot) in both if p.columns is None]

    @functools.cache
    def rigid_torque() -> np.ndarray:  # every sample's, once: a load_friction's columns read it in every pass
        return Motion(adapter.robot, adapter.q, adapter.qd, adapter.qdd).rigid_torque

    def fill(rows, keep=None) -> dict:
        out = {r: np.empty((len(rows), w)) for r, w in width.items()}
        for i, cols, slot in given:
            if keep is None or keep[i]:
                for j, c in cols.items():
                    out[adapter.row_of[j]][:, slot[adapter.row_of[j]]] = c[rows]
        m = Motion(adapter.robot, adapter.q[rows], adapter.qd[rows], adapter.qdd[rows], lambda: rigid_torque()[rows])
        for i, term, slot in own:
            if keep is None or keep[i]:
                X = motion_columns(term, m)
                for r, cs in slot.items():
                    out[r][:, cs] = X[:, adapter.rows[r]]
        return out

    return fill
