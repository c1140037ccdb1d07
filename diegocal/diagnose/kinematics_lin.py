"""Linearisation of the kinematic observation model at a fit, for the candidates of
:mod:`diegocal.diagnose.kinematics` (thesis eq. 2.10-2.23).

A candidate term's columns ∂(prediction)/∂θ_term are made comparable with the baseline's residual
in two steps:

1. the Schur complement of each frame's q (eq. 2.22-2.23), :meth:`Linearised.project`,

   .. math:: c_t \\leftarrow c_t - J_t (J_t^T W J_t)^{-1} J_t^T W c_t,

   J_t the observation Jacobian w.r.t. q_t, W = diag(1/σ²) the sensors' weights, so that no term
   is "explained" by moving q;
2. Frisch-Waugh-Lovell against the calibration STAC fits once for the whole log (θ of eq. 2.10:
   every pot's gain and bias, every marker's position, the mocap frame),
   :meth:`Linearised.beyond_calibration`: the projected calibration directions are fitted to the
   columns on the training frames and what they cannot do is kept. STAC's residual is already
   orthogonal to those directions, so fitting it on the kept columns equals fitting it on the term
   and the whole calibration at once, without the (T, R, k0) re-fit columns (k0 = 2P + 3M + 6:
   154 on Diego San). Directions the calibration takes up entirely are dropped (a joint origin
   moved along its axis is the markers' positions when the axes below are parallel to it; moved
   across the link, angle offsets of the joint and its parent, i.e. pot biases).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from diegocal.stac.covariance import block_sandwich, standard_errors
from diegocal.stac.loo import BATCH, FrameProjection, deleted_residuals
from diegocal.stac.model import Observation

#: A candidate acts on the channels that carry at least this share of its largest channel's
#: weighted column energy (its projection spreads tiny parts over every sensor of the chain).
CHANNEL_SHARE = 0.02
#: A direction of a term keeps less than this fraction of its squared norm once the calibration's
#: span is projected out: the calibration takes it up (not identifiable).
IDENTIFIABLE = 1e-6
#: Frames per block of a :class:`Sweep`, and columns projected together on a block
#: (:meth:`Sweep._each`): a block's transients are a few arrays of SWEEP_FRAMES x R x
#: PROJECT_COLUMNS floats (7 MB on Diego San), the same for any log's length.
SWEEP_FRAMES = BATCH
PROJECT_COLUMNS = 32
#: The dtype a candidate's columns are kept in (:meth:`Linearised.channels`): float32. They are
#: the engine's regressors, held for every candidate of a round (most of the diagnosis's memory),
#: and only read: projected and orthogonalised in float64 first, each kept to 7 digits, which moves
#: a least-squares coefficient by ~1e-7 of itself on a well-conditioned design, far inside its
#: standard error (the engine reads them back as float64).
COLUMN_DTYPE = np.float32


@dataclass
class Linearised:
    """The observation Jacobian and the Schur projector of every frame of a block of the log at a
    fit (mapped rows: P pots, then 3 per mapped marker): the whole log's (:meth:`at`) or one block
    of a :class:`Sweep`'s (frames ``start`` to ``start + T``).

    J : (T, R, n); Hi : (T, n, n) = (JᵀWJ + D)⁻¹, so that K = Hi JᵀW (T, n, R) (:attr:`K`, formed
    only where asked: Hi is a third of its size, and every product with K is one with Hi after
    one with JᵀW); w : (T, R) weights 1/σ² (0 where occluded); D : (T, n) the tiny diagonal that
    keeps JᵀWJ invertible
    """

    adapter: object  # the KinematicsAdapter (its robot)
    fitted: object  # the KinFit linearised at
    obs: Observation
    params: object
    J: np.ndarray
    Hi: np.ndarray
    w: np.ndarray
    s: np.ndarray
    Rl: np.ndarray
    sigma_p: np.ndarray
    D: np.ndarray
    start: int = 0
    _cal_gram: np.ndarray | None = None
    _cal_pinv: np.ndarray | None = None
    _U: np.ndarray | None = None
    _N: tuple | None = None
    _poses: object = None
    _RRl: np.ndarray | None = None
    _x: np.ndarray | None = None
    _xs: np.ndarray | None = None

    @property
    def T(self) -> int:
        return self.J.shape[0]

    @property
    def R(self) -> int:
        return self.J.shape[1]

    @property
    def P(self) -> int:
        return self.obs.n_pots

    @property
    def frames(self) -> slice:
        """The log's frames this linearisation covers."""
        return slice(self.start, self.start + self.T)

    @property
    def train(self) -> np.ndarray:
        """(T,) bool: the training frames among them."""
        return self.fitted.train[self.frames]

    @property
    def K(self) -> np.ndarray:
        """(T, n, R) = (JᵀWJ + D)⁻¹ JᵀW of every frame (formed on each call: for tests and
        :meth:`deleted_residuals`)."""
        return self.Hi @ (np.swapaxes(self.J, 1, 2) * self.w[:, None, :])

    def project(self, C: np.ndarray) -> np.ndarray:
        """Columns (T, R, k) minus their part along the frame's q directions (module docstring):
        c − J Hi Jᵀ W c."""
        if C.shape[-1] > 3:
            return C - self.J @ (self.Hi @ (np.swapaxes(self.J, 1, 2) @ (self.w[..., None] * C)))
        out = np.empty(C.shape)
        for k in range(C.shape[-1]):  # a column at a time: einsum beats batched matmul twice over
            c = C[..., k]
            v = np.einsum("tnm,tm->tn", self.Hi, np.einsum("trn,tr->tn", self.J, self.w * c))
            out[..., k] = c - np.einsum("trn,tn->tr", self.J, v)
        return out

    def pot_units(self) -> np.ndarray:
        """The projected unit columns of every pot (T, R, P): e_j − J K e_j, made once per block
        (a round's pot candidates all read them)."""
        if self._U is None:  # made whole before it is kept: a sweep's producer and consumer share a block
            P = self.P
            KP = self.Hi @ (np.swapaxes(self.J[:, :P], 1, 2) * self.w[:, None, :P])  # K[:, :, :P]
            U = -(self.J @ KP)
            U[:, np.arange(P), np.arange(P)] += 1.0
            self._U = U
        return self._U

    def project_pot(self, j: int) -> np.ndarray:
        """The projected unit column of pot j: (T, R)."""
        return self.pot_units()[:, :, j]

    def pot_span(self, pots) -> np.ndarray:
        """(T, R, 2 len(pots)): the projected gain and bias columns (s_i e_i, e_i projected) of
        ``pots``, in that order (the last set asked for is kept: a pot's candidates come together)."""
        pots, kept = tuple(pots), self._N  # read once: another thread may keep another set meanwhile
        if kept is None or kept[0] != pots:
            U = self.pot_units()
            cols = [c for i in pots for c in (U[:, :, i] * self.s[:, i, None], U[:, :, i])]
            kept = self._N = (pots, np.stack(cols, axis=-1))
        return kept[1]

    def pot_gram(self) -> np.ndarray:
        """(2P, 2P): the weighted Gram matrix over the training frames of every pot's projected
        gain and bias columns (:meth:`pot_span` of every pot), 50 frames at a time."""
        U, s, wt = self.pot_units(), self.s, self.w * self.train[:, None]
        P = self.P
        out = np.zeros((2 * P, 2 * P))
        for a in range(0, self.T, 50):
            f = slice(a, a + 50)
            N = np.empty((*U[f].shape[:2], 2 * P))
            N[..., 0::2], N[..., 1::2] = U[f] * s[f][:, None, :], U[f]
            out += weighted_gram(N, wt[f])
        return out

    def residual_rows(self) -> np.ndarray:
        """(T, R) residuals of the mapped rows (reading − prediction)."""
        a, f, sl = self.fitted.applied, self.fitted, self.frames
        rp = np.asarray(a.log.stream("pots").data[sl], float) - f.pots[sl]
        rm = np.asarray(a.log.stream("markers").data[sl], float) - f.markers[sl]
        return np.concatenate([rp, rm.reshape(self.T, -1)], axis=1)

    def deleted_residuals(self) -> tuple[np.ndarray, np.ndarray]:
        """Each sensor's residual with q tracked from every other sensor of its frame:
        :func:`diegocal.stac.loo.deleted_residuals` at this fit."""
        proj = FrameProjection(self.J, self.K, self.w, self.s, self.Rl, self.sigma_p, self.D)
        return deleted_residuals(proj, self.residual_rows(), self.P)

    def marker_basis(self, m: int) -> np.ndarray:
        """∂x_m/∂d_m = R Rl (T, R, 3) on marker m's rows."""
        C = np.zeros((self.T, self.R, 3))
        P = self.P
        C[:, P + 3 * m : P + 3 * m + 3] = self.RRl[:, m]
        return C

    def link_offset_basis(self, joint: str) -> np.ndarray:
        """∂x/∂δ (T, R, 3) of a translation δ of the joint's origin in its parent joint's frame:
        every marker it moves shifts by R R_parent δ (linear pots: not modelled, rows 0)."""
        kin = self.obs.kin
        k = self.adapter.robot.joint_index(joint)
        if self._poses is None:  # every joint's candidate of the block reads them
            self._poses = kin.joint_poses(self.fitted.q[self.frames])
        par = kin.parent[k]
        Rp = self._poses.R[:, par] if par >= 0 else self._poses.root_R
        RRp = np.einsum("ij,tjk->tik", self.params.R, Rp)
        C = np.zeros((self.T, self.R, 3))
        P = self.P
        for m, sgn in enumerate(marker_moves(self.obs, self.adapter.robot, joint)):
            if sgn:
                C[:, P + 3 * m : P + 3 * m + 3] = sgn * RRp
        return C

    # ------------------------------------------------------------------ the calibration's span
    @property
    def RRl(self) -> np.ndarray:
        """R R_l (T, M, 3, 3): each marker's link frame in the mocap frame."""
        if self._RRl is None:
            self._RRl = np.einsum("ij,tmjk->tmik", self.params.R, self.Rl)
        return self._RRl

    @property
    def x_mocap(self) -> np.ndarray:
        """Predicted markers relative to the mocap translation (T, M, 3), m (0 where missing)."""
        if self._x is None:
            self._x = np.nan_to_num(self.fitted.markers[self.frames] - self.params.T)
        return self._x

    @property
    def x_skew(self) -> np.ndarray:
        """[x]× (T, M, 3, 3) of :attr:`x_mocap`."""
        if self._xs is None:
            self._xs = _skew(self.x_mocap)
        return self._xs

    def _calibration_basis(self, sl: slice) -> np.ndarray:
        """∂(prediction)/∂θ_cal (B, R, k0) on frames ``sl`` for every parameter STAC fits once for
        the whole log (thesis eq. 2.10): each pot's gain and bias, each marker's position on its
        link, the mocap frame's translation and (small) rotation."""
        P, M = self.P, self.obs.n_markers
        s = self.s[sl]
        B = s.shape[0]
        F = np.zeros((B, self.R, 2 * P + 3 * M + 6))
        i = np.arange(P)
        F[:, i, 2 * i] = s
        F[:, i, 2 * i + 1] = 1.0
        x = self.x_mocap[sl]
        c = 2 * P + 3 * M
        for m in range(M):
            rows = slice(P + 3 * m, P + 3 * m + 3)
            F[:, rows, 2 * P + 3 * m : 2 * P + 3 * m + 3] = self.RRl[sl, m]
            F[:, rows, c : c + 3] = np.eye(3)
            for k in range(3):  # d/dω of exp([ω]×) x at ω = 0: e_k × x
                F[:, rows, c + 3 + k] = np.cross(np.eye(3)[k], x[:, m])
        return F

    def _calibration_dot(self, V: np.ndarray) -> np.ndarray:
        """Fᵀ V (k0, k) summed over frames, for rows V (T, R, k) (F: :meth:`_calibration_basis`),
        from F's structure rather than F itself."""
        P, M = self.P, self.obs.n_markers
        k = V.shape[-1]
        out = np.zeros((2 * P + 3 * M + 6, k))
        out[0 : 2 * P : 2] = np.einsum("tp,tpk->pk", self.s, V[:, :P])
        out[1 : 2 * P : 2] = V[:, :P].sum(axis=0)
        Vm = V[:, P:].reshape(V.shape[0], M, 3, k)
        out[2 * P : 2 * P + 3 * M] = np.einsum("tmil,tmik->mlk", self.RRl, Vm).reshape(3 * M, k)
        c = 2 * P + 3 * M
        out[c : c + 3] = Vm.sum(axis=(0, 1))
        out[c + 3 : c + 6] = np.einsum("tmij,tmjk->ik", self.x_skew, Vm)  # (e_j × x)·v = (x × v)_j
        return out

    def _calibration_apply(self, beta: np.ndarray) -> np.ndarray:
        """F β (T, R, k) for coefficients β (k0, k)."""
        P, M = self.P, self.obs.n_markers
        k = beta.shape[-1]
        out = np.empty((self.T, self.R, k))
        out[:, :P] = self.s[..., None] * beta[0 : 2 * P : 2][None] + beta[1 : 2 * P : 2][None]
        c = 2 * P + 3 * M
        xm = self.RRl @ beta[2 * P : c].reshape(M, 3, k) + beta[c : c + 3][None, None]
        xm -= (self.x_skew.reshape(-1, 3) @ beta[c + 3 : c + 6]).reshape(xm.shape)  # ω × x = −[x]× ω
        out[:, P:] = xm.reshape(self.T, 3 * M, k)
        return out

    def _op_basis(self, op: np.ndarray, f) -> np.ndarray:
        """op F (B, n, k0) for a per-frame operator op (B, n, R) on frames ``f``, from F's
        structure (:meth:`_calibration_basis`)."""
        P, M = self.P, self.obs.n_markers
        B, n = op.shape[:2]
        out = np.empty((B, n, 2 * P + 3 * M + 6))
        out[:, :, 0 : 2 * P : 2] = op[:, :, :P] * self.s[f][:, None, :]
        out[:, :, 1 : 2 * P : 2] = op[:, :, :P]
        om = op[:, :, P:].reshape(B, n, M, 3)
        out[:, :, 2 * P : 2 * P + 3 * M] = np.einsum("tnmi,tmik->tnmk", om, self.RRl[f]).reshape(B, n, 3 * M)
        c = 2 * P + 3 * M
        out[:, :, c : c + 3] = om.sum(axis=2)
        out[:, :, c + 3 : c + 6] = -np.einsum("tnmi,tmik->tnk", om, self.x_skew[f])  # e_k × x = −[x]× e_k
        return out

    def _gram(self) -> np.ndarray:
        """(S F)ᵀ W (S F) over the training frames (k0, k0) (:meth:`_gram_part`), its
        pseudo-inverse kept beside it."""
        if self._cal_gram is None:  # the inverse kept first: a reader that sees the Gram matrix uses both
            G = self._gram_part()
            G = 0.5 * (G + G.T)
            self._cal_pinv = np.linalg.pinv(G, rcond=1e-10, hermitian=True)
            self._cal_gram = G
        return self._cal_gram

    def _gram_part(self) -> np.ndarray:
        """(S F)ᵀ W (S F) over these training frames (k0, k0), S = I − J K the per-frame q projector:
        Fᵀ W F − (Jᵀ W F)ᵀ K F − (K F)ᵀ D (K F) (expand it with Jᵀ W J = H − D, K = H⁻¹ Jᵀ W);
        Fᵀ W F from F's structure (the markers' rows are orthonormal R R_l, weighted alike on their
        three axes). Not yet symmetrised: a sweep adds the blocks' parts first."""
        P, M = self.P, self.obs.n_markers
        tr = self.train
        w, s = self.w[tr], self.s[tr]
        k0 = 2 * P + 3 * M + 6
        G = np.zeros((k0, k0))  # upper triangle first
        i = np.arange(P)
        G[2 * i, 2 * i] = np.einsum("tp,tp->p", w[:, :P], s * s)
        G[2 * i, 2 * i + 1] = np.einsum("tp,tp->p", w[:, :P], s)
        G[2 * i + 1, 2 * i + 1] = w[:, :P].sum(axis=0)
        wm = w[:, P::3]  # (T, M): one weight per marker
        Q, X = self.RRl[tr], self.x_skew[tr]  # (T, M, 3, 3)
        c = 2 * P + 3 * M
        QtT = np.einsum("tm,tmji->mij", wm, Q)  # Σ w Qᵀ
        QtX = -np.einsum("tm,tmji,tmjk->mik", wm, Q, X)  # Σ w Qᵀ (−[x]×)
        for m in range(M):
            r = slice(2 * P + 3 * m, 2 * P + 3 * m + 3)
            G[r, r] = wm[:, m].sum() * np.eye(3)
            G[r, c : c + 3], G[r, c + 3 : c + 6] = QtT[m], QtX[m]
        G[c : c + 3, c : c + 3] = wm.sum() * np.eye(3)
        G[c : c + 3, c + 3 : c + 6] = -np.einsum("tm,tmik->ik", wm, X)
        G[c + 3 : c + 6, c + 3 : c + 6] = np.einsum("tm,tmji,tmjk->ik", wm, X, X)
        G = np.triu(G) + np.triu(G, 1).T
        frames = np.flatnonzero(tr)
        for a in range(0, frames.size, 250):
            f = frames[a : a + 250]
            JW = np.swapaxes(self.J[f], 1, 2) * self.w[f][:, None, :]
            A, B = self._op_basis(JW, f), self._op_basis(self.Hi[f] @ JW, f)
            G -= A.reshape(-1, k0).T @ B.reshape(-1, k0) + weighted_gram(B, self.D[f])
        return G

    def beyond_calibration(self, C: np.ndarray) -> np.ndarray:
        """Projected columns (T, R, k) minus their weighted least-squares fit, on the training
        frames, by the projected calibration basis (:meth:`_calibration_basis`): what a term does
        that no re-fit of the pots' gains and biases, the markers' positions and the mocap frame
        (and no per-frame q) can do. The baseline's residual is already orthogonal to those
        directions (STAC's fit is their optimum), so by Frisch-Waugh-Lovell fitting the residual on
        these columns alone equals fitting it on the term and a re-fit of the whole calibration.
        Directions of the term that the calibration takes up entirely (a joint origin moved along
        the joint's axis when the axes below are parallel to it: the markers' positions) are set to
        zero rather than left as numerical noise (:func:`_identifying`). On these frames alone: a
        :class:`Sweep` fits over the whole log a block at a time."""
        C = np.nan_to_num(C)
        wt = self.w * self.train[:, None]
        b = self._calibration_dot(wt[..., None] * C)  # (S F)ᵀ W C = Fᵀ W C, as S C = C
        self._gram()
        out = C - self.project(self._calibration_apply(self._cal_pinv @ b))
        M = identifying(weighted_gram(out, wt), weighted_gram(C, wt))
        return out if M is None else out @ M


def marker_moves(obs: Observation, robot, joint: str) -> np.ndarray:
    """(M,) +1 / −1 / 0: whether a translation of the joint's origin moves each marker (the markers
    below it, relative to the mocap frame's link)."""
    kin = obs.kin
    k = robot.joint_index(joint)
    jl, _, _ = kin.link_info(obs.marker_links)
    return kin._anc[jl, k].astype(float) - kin._anc[kin.base_joint, k]


def identifying(gram: np.ndarray, raw: np.ndarray) -> np.ndarray | None:
    """The map (k, k) onto the directions of orthogonalised columns whose weighted Gram matrix is
    ``gram`` that kept at least IDENTIFIABLE of their squared norm before (``raw``: the Gram matrix
    of the columns before); None when every direction did. The others the calibration takes up:
    they are set to zero rather than left as numerical noise."""
    lam, V = np.linalg.eigh(gram)
    before = np.einsum("kl,ka,la->a", raw, V, V)
    gone = lam <= IDENTIFIABLE * np.maximum(before, 1e-300)
    if not gone.any():
        return None
    keep = V[:, ~gone]
    return keep @ keep.T


def step_errors(bread: np.ndarray, scores: np.ndarray) -> np.ndarray:
    """Standard errors (k,) of a Gauss-Newton step's coefficients, from AᵀWA (k, k) over the rows
    of the fit and each frame's score Aᵀ W e (T, k) at the step (e the residual after it; frames
    outside the fit 0), as STAC's own (:func:`diegocal.stac.covariance.block_sandwich`): the
    sandwich over contiguous blocks of frames, at least the model-based (AᵀWA)⁻¹ (the residuals are
    correlated in time; the frames of one block share their errors). A coefficient with a share
    in a direction the data do not fix (AᵀWA's eigenvalue under :data:`UNFIXED` of its largest: a
    link offset along what the markers' own positions absorb) has an infinite standard error: the
    step leaves it where it was, which the data neither confirm nor refute."""
    w, v = np.linalg.eigh(bread)
    fixed = w > UNFIXED * max(float(w.max()), 0.0)
    inv = (v[:, fixed] / w[fixed]) @ v[:, fixed].T  # the pseudo-inverse, over the directions the data fix
    robust, _ = block_sandwich(inv, scores)
    se = standard_errors(inv, robust)
    se[(v[:, ~fixed] ** 2).sum(axis=1) > 1e-6] = np.inf
    return se


#: Below this share of AᵀWA's largest eigenvalue a direction is not fixed by the data (the pseudo-
#: inverse's cut-off, relative).
UNFIXED = 1e-12


def _skew(x: np.ndarray) -> np.ndarray:
    """[x]× (..., 3, 3) of vectors x (..., 3): [x]× v = x × v."""
    out = np.zeros((*x.shape, 3))
    out[..., 0, 1], out[..., 0, 2] = -x[..., 2], x[..., 1]
    out[..., 1, 0], out[..., 1, 2] = x[..., 2], -x[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -x[..., 1], x[..., 0]
    return out


def weighted_gram(A: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Σ_rows w A Aᵀ (k, k) for columns A (..., k) and row weights w (...) (BLAS, not einsum)."""
    X = (A * np.sqrt(w)[..., None]).reshape(-1, A.shape[-1])
    return X.T @ X


def row_gram(C: np.ndarray, root_w: np.ndarray) -> np.ndarray:
    """Σ over frames of w C Cᵀ per mapped row (R, k, k), for columns C (B, R, k) and the square
    roots of their weights ``root_w`` (B, R)."""
    X = np.swapaxes(C, 0, 1) * root_w.T[..., None]  # (R, B, k)
    return np.swapaxes(X, 1, 2) @ X


def running_median(x: np.ndarray, half: int, chunk: int = 1024) -> np.ndarray:
    """NaN-aware running median over ±half samples along axis 0 of (T, ...), ``chunk`` samples at
    a time: the windows of a whole long log at once are (T, ..., 2·half + 1) floats."""
    pad = np.concatenate([np.full((half, *x.shape[1:]), np.nan), x, np.full((half, *x.shape[1:]), np.nan)])
    out = np.empty(x.shape)
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        for a in range(0, x.shape[0], chunk):
            b = min(a + chunk, x.shape[0])
            out[a:b] = np.nanmedian(sliding_window_view(pad[a : b + 2 * half], 2 * half + 1, axis=0), axis=-1)
    return out
