"""STAC q-phase: per-frame joint angles with θ fixed, damped Gauss-Newton (thesis §2.3.4, eq. 2.21).

Each frame t solves, independently (eq. 2.6),

.. math:: q_t^* = \\arg\\min_{q_t} \\sum_m \\rho(\\|\\hat x_{mt} - x_{mt}\\| / \\sigma_x)
          + \\sum_j \\rho((\\hat p_{jt} - p_{jt}) / \\sigma_{p,kind(j)})

with ρ(z) = z²/2 (Gaussian, eq. 2.21) or, for the markers only, a robust loss (Huber's or
Tukey's, :mod:`.robust`); the pots stay Gaussian. One Levenberg-Marquardt step per call:
the batched normal equations ``(JᵀWJ + λ diag(JᵀWJ)) δ = −JᵀW r`` are solved per frame, the
step is projected onto the joint limits, and each frame keeps its own damping λ_t (accept: λ/3,
reject: λ·4). J (eq. 2.22 pots, eq. 2.23 markers) is never formed: JᵀWJ and JᵀW r are summed
from its structure (:func:`normal_equations`), and JᵀWJ is block diagonal over the joints that
share no sensor (diego: torso, head and arms; each leg), so each block is solved on its own.
A step ends with the forward kinematics at the q it returns (the candidate's, kept per frame),
held in the returned :class:`~diegocal.stac.model.State`: the joint step and the next step at
that q linearise from it, so each q costs one pass of the kinematics.
Batches of frames (``batch_size``, 250: their arrays stay in cache) run in threads (``jobs``):
numpy releases the GIL in the heavy products, and no robot model is pickled.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
from threadpoolctl import threadpool_limits

from diegocal.stac import robust
from diegocal.stac.loo import frame_slices
from diegocal.stac.model import MARKERS, Observation, Params, State
from diegocal.stac.pphase import CHUNK
from diegocal.stac.robust import MIN_REDUNDANCY, floor_factor


@dataclass(frozen=True)
class Noise:
    """Per-reading noise levels: sig_p (P,) in V and sig_x in m, plus loss settings."""

    sig_p: np.ndarray
    sig_x: float
    loss: str = "linear"
    huber: float = 3.0
    use_pots: bool = True
    use_markers: bool = True


def rho(z: np.ndarray, loss: str, k: float) -> np.ndarray:
    """Loss of standardised residuals z (any shape): z²/2, Huber or Tukey (:func:`.robust.rho`)."""
    return robust.rho(z, loss, k)


def irls_weight(z: np.ndarray, loss: str, k: float) -> np.ndarray:
    """IRLS weight ρ'(z)/z (:func:`.robust.weight`)."""
    return robust.weight(z, loss, k)


def residuals(obs: Observation, params: Params, noise: Noise, s, Rl, pl, pots, markers, valid):
    """Standardised residuals of a batch: pots (B, P), marker norms (B, M) and vectors (B, M, 3)."""
    return _residuals(params, noise, s, Rl, pl, pots, markers, valid)[:3]


def _residuals(params: Params, noise: Noise, s, Rl, pl, pots, markers, valid):
    """:func:`residuals` and the markers in the base frame xb (B, M, 3) (eq. 2.11), which the
    normal equations use too."""
    zp = (params.gain * s + params.bias - pots) / noise.sig_p
    xb = base_points(Rl, pl, params.xyz)
    B, M = xb.shape[:2]
    rx = (xb.reshape(B * M, 3) @ params.R.T).reshape(B, M, 3)  # one product, not one per frame
    rx += params.T
    rx -= markers
    rx /= noise.sig_x
    rx[~valid] = 0.0  # occluded (NaN) markers
    return zp, np.sqrt(np.einsum("bmi,bmi->bm", rx, rx)), rx, xb


def base_points(Rl: np.ndarray, pl: np.ndarray, xyz: np.ndarray) -> np.ndarray:
    """The markers in the base frame x_b = R_l d + p_l (B, M, 3), m (eq. 2.11), for their links'
    poses Rl (B, M, 3, 3), pl (B, M, 3) and positions xyz (M, 3): three multiply-adds over the
    whole arrays (a broadcast matmul is one tiny product per frame and marker)."""
    xb = Rl[..., 0] * xyz[:, 0, None]
    xb += Rl[..., 1] * xyz[:, 1, None]
    xb += Rl[..., 2] * xyz[:, 2, None]
    xb += pl
    return xb


def frame_cost(obs, params, noise, s, Rl, pl, pots, markers, valid) -> np.ndarray:
    """Per-frame objective of eq. 2.21 (B,)."""
    zp, zx, _, _ = _residuals(params, noise, s, Rl, pl, pots, markers, valid)
    c = np.zeros(s.shape[0])
    if noise.use_pots:
        c += 0.5 * (zp * zp).sum(1)  # pots: Gaussian under every loss (robust.py)
    if noise.use_markers:
        c += rho(zx, noise.loss, noise.huber).sum(1)
    return c


@dataclass(frozen=True)
class BlockDiag:
    """A block-diagonal n x n matrix per frame, as its blocks: ``blocks[i]`` (B, k_i, k_i) on the
    joints ``index[i]`` (k_i,) (:attr:`~diegocal.stac.model.Sparsity.blocks`); zero between them.
    The q-phase's JᵀWJ is one: its blocks are formed, damped, solved and inverted on their own."""

    blocks: tuple
    index: tuple
    n: int

    def dense(self) -> np.ndarray:
        """The full matrices (B, n, n)."""
        out = np.zeros((self.blocks[0].shape[0], self.n, self.n))
        for ix, h in zip(self.index, self.blocks, strict=True):
            out[:, ix[:, None], ix] = h
        return out

    def take(self, k) -> BlockDiag:
        """The frames ``k`` (an index array)."""
        return BlockDiag(tuple(h[k] for h in self.blocks), self.index, self.n)

    @staticmethod
    def concat(parts: list) -> BlockDiag:
        """The frames of ``parts`` (BlockDiags of the same blocks), one after another."""
        blocks = tuple(np.concatenate(hs) for hs in zip(*(p.blocks for p in parts), strict=True))
        return BlockDiag(blocks, parts[0].index, parts[0].n)


def normal_equations(
    obs: Observation, params: Params, noise: Noise, q: np.ndarray, sl: slice, want_red: bool = True, st=None
):
    """JᵀWJ (a :class:`BlockDiag` on ``obs.sparsity.blocks``, B frames), gradient JᵀW r (B, n),
    per-frame cost (B,), the evaluation at q[sl], the redundancy of each sensor type (dict,
    summed over the batch; see :func:`redundancy`) and the linearisation with the robust weights
    (dict, for the joint step).

    J is eq. 2.22 (pots) and eq. 2.23 (markers), never formed densely: rotary/encoder/tendon pots
    have the constant ∂s/∂q = A, the linear pots' rows are few, and the markers' sums come from
    the joint twists (:meth:`diegocal.robot.batch.BatchKinematics.points_normal_blocks`). ``st``:
    the :class:`State` at this very q (T frames); its kept linearisation, if any, replaces the
    forward kinematics.
    """
    q = q[sl]
    pots, markers, valid = obs.pots[sl], obs.markers[sl], obs.valid[sl]
    lin = st.linearisation(sl) if st is not None else None
    lin = obs.linearise(q) if lin is None else lin
    s, Rl, pl = lin.s, lin.Rl, lin.pl
    zp, zx, rx, xb = _residuals(params, noise, s, Rl, pl, pots, markers, valid)
    B, n = q.shape
    sp = obs.sparsity
    parts = {}  # per sensor type: its entries of H, as (Sparsity's place in the blocks, values (B, k))
    wp = np.zeros_like(zp)
    wx = x = None
    if noise.use_markers and obs.n_markers:  # the markers' sums first: H starts from them
        wx = irls_weight(zx, noise.loss, noise.huber) * valid
        x = xb  # markers in the base frame (eq. 2.11)
        f = (rx.reshape(-1, 3) @ params.R).reshape(rx.shape)
        f *= (wx / noise.sig_x)[..., None]  # w Rᵀ z / σ_x (eq. 2.23 with R)
        Hb, g = obs.kin.points_normal_blocks(None, x, obs.marker_links, wx / noise.sig_x**2, f, sp.blocks, lin.xi)
        parts[MARKERS] = None  # the rest of H
        c0 = rho(zx, noise.loss, noise.huber).sum(1)
    else:
        Hb, g, c0 = tuple(np.zeros((B, len(ix), len(ix))) for ix in sp.blocks), np.zeros((B, n)), np.zeros(B)
    if noise.use_pots and obs.n_pots:
        kp = params.gain / noise.sig_p  # eq. 2.22: ∂z_p/∂q = (gain / σ_p) ∂s/∂q
        wp = np.ones_like(zp)  # pots: Gaussian under every loss (robust.py)
        wz = wp * zp * kp
        g += wz @ obs.A
        for kind, (idx, _, outer) in sp.pot_flat.items():
            parts[kind] = (sp.pot_local[kind], (wp[:, idx] * kp[idx] ** 2) @ outer)
        if len(obs.linear):
            Jl = lin.ds_lin * kp[obs.linear, None]
            g[:, sp.lin_cols] += np.einsum("blc,bl->bc", lin.ds_lin, wz[:, obs.linear])
            parts["linear"] = (sp.lin_local, (np.swapaxes(Jl, 1, 2) @ (Jl * wp[:, obs.linear, None])).reshape(B, -1))
        for i, h in enumerate(Hb):
            flat = h.reshape(B, -1)
            for where, vals in (p for p in parts.values() if p is not None):
                sel, loc = where[i]
                flat[:, loc] += vals[:, sel]
        c0 += 0.5 * (zp * zp).sum(1)
    H = BlockDiag(Hb, sp.blocks, n)
    extra = {"lin": lin, "wp": wp, "zp": zp, "wx": wx, "rx": rx, "valid": valid, "x": x}
    return H, g, c0, (s, Rl, pl), redundancy(H, parts) if want_red else {}, extra


def damped(H: BlockDiag, lam: np.ndarray, inplace: bool = False) -> BlockDiag:
    """H + λ diag(H) + ε I per frame (Levenberg-Marquardt, with a tiny ridge for joints no
    sensor sees; ε from the largest diagonal entry of the frame's whole H): λ (B,); ``inplace``
    overwrites H's blocks."""
    blocks = H.blocks if inplace else tuple(h.copy() for h in H.blocks)
    diags = [np.einsum("bii->bi", h) for h in blocks]
    ridge = 1e-9 * (1.0 + np.max([d.max(1) for d in diags], axis=0)[:, None])
    lam = lam[:, None]
    for diag in diags:
        diag += lam * diag + ridge
    return H if inplace else BlockDiag(blocks, H.index, H.n)


def map_batches(fn, T: int, batch: int, jobs: int = 1) -> list:
    """[fn(slice) for each batch of ``batch`` frames out of T], in ``jobs`` threads (numpy
    releases the GIL in the heavy products; the results do not depend on ``jobs``)."""
    slices = frame_slices(T, batch)
    if jobs > 1 and len(slices) > 1:
        with threadpool_limits(limits=1, user_api="blas"), ThreadPoolExecutor(jobs) as pool:
            return list(pool.map(fn, slices))  # one BLAS thread per worker
    return [fn(sl) for sl in slices]


def block_solve(A: BlockDiag, b: np.ndarray) -> np.ndarray:
    """A⁻¹ b per frame, block by block; b (B, n) or (B, n, k)."""
    vec = b.ndim == 2
    b = b[..., None] if vec else b
    out = np.zeros(b.shape)
    for ix, a in zip(A.index, A.blocks, strict=True):
        out[:, ix] = np.linalg.solve(a, b[:, ix])
    return out[..., 0] if vec else out


def spd_inverse(A: np.ndarray) -> np.ndarray:
    """A⁻¹ per frame for symmetric positive definite A (B, k, k): A = L Lᵀ (Cholesky), then
    A⁻¹ = L⁻ᵀ L⁻¹, a third of the flops of the LU inverse (``np.linalg.inv`` solves A X = I);
    the LU inverse where a frame's A is not numerically positive definite."""
    try:
        L = np.linalg.cholesky(A)
    except np.linalg.LinAlgError:
        return np.linalg.inv(A)
    # L⁻¹ by forward substitution, row by row, every frame at once, each row written over L's
    # (row i of L is last read to make row i of L⁻¹): one array of temporaries less per call
    d = 1.0 / np.einsum("bii->bi", L)
    for i in range(L.shape[1]):
        r = -(L[:, i : i + 1, :i] @ L[:, :i, : i + 1])[:, 0]
        r[:, i] += 1.0
        L[:, i, : i + 1] = r * d[:, i : i + 1]
    return np.swapaxes(L, 1, 2) @ L


def redundancy(H: BlockDiag, parts: dict) -> dict:
    """Variance-component redundancy per sensor type: tr(H⁻¹ H_g) summed over frames.

    Fitting q_t absorbs n degrees of freedom per frame; the share of type g is the trace of
    its block of the hat matrix, tr((JᵀWJ)⁻¹ J_gᵀ W J_g). §2.3.5's re-estimate σ_g² = RSS_g / N_g
    ignores this and collapses to 0 when a type can be fitted exactly (one rotary pot per joint);
    σ_g² = RSS_g / (N_g − tr_g) (Helmert/Förstner variance-component estimation) does not.

    H = Σ_g H_g; ``parts`` gives each H_g as (per block of H, which of its values and their flat
    indices in the block: :attr:`~diegocal.stac.model.Sparsity.pot_local`) and values (B, k),
    or None for (at most) one type, whose share is the rest: Σ_g tr(H⁻¹ H_g) = n − ε tr(H⁻¹) with
    H⁻¹ = (H + ε I)⁻¹. Returns {group: Σ_t tr_g}.
    """
    B, n = H.blocks[0].shape[0], H.n
    eps = 1e-9 * (1.0 + sum(np.einsum("bii->b", h) for h in H.blocks))
    out = {g: 0.0 for g, p in parts.items() if p is not None}
    ridge = 0.0  # Σ_t ε_t tr(H_t⁻¹)
    for i, h in enumerate(H.blocks):  # H⁻¹ block by block (it is block diagonal too)
        diag = np.einsum("bii->bi", h)  # H + ε I in H's own block (no copy), its diagonal put back after
        kept = diag.copy()
        diag += eps[:, None]
        try:
            Hi = spd_inverse(h)
        finally:
            diag[...] = kept
        ridge += float(eps @ np.einsum("bii->b", Hi))
        flat = Hi.reshape(B, -1)
        for g, (where, vals) in ((g, p) for g, p in parts.items() if p is not None):
            sel, loc = where[i]  # H_g's entries in this block (an entry never straddles two)
            out[g] += float(np.vdot(flat[:, loc], vals[:, sel]))  # H_g, Hi symmetric
    for g in (g for g, p in parts.items() if p is None):
        out[g] = B * n - ridge - sum(out.values())
    return out


def _lm_batch(obs: Observation, params: Params, noise: Noise, q, lam, sl, want_red, st, cand, c0, base) -> dict:
    """The damped Gauss-Newton step on the frames ``sl``: the candidate q, projected onto the
    joint limits, into ``cand`` and the cost at q into ``c0``; without a kept linearisation
    (``st``) the one made here goes into ``base`` (the frames whose step fails keep it). Returns
    the batch's redundancy."""
    H, g, c, _, red, ex = normal_equations(obs, params, noise, q, sl, want_red, st)
    delta = block_solve(damped(H, lam[sl], inplace=True), g)
    np.clip(q[sl] - delta, obs.lower, obs.upper, out=cand[sl])  # projection onto the joint limits
    c0[sl] = c
    if base is not None:
        _put(base, sl, ex["lin"])
    return red


def _try_batch(obs: Observation, params: Params, noise: Noise, cand, sl, new: State, c1) -> None:
    """Forward kinematics and cost (into ``new`` and ``c1``) at the candidates of the frames ``sl``."""
    lin = obs.linearise(cand[sl])
    _put(new, sl, lin)
    c1[sl] = frame_cost(obs, params, noise, lin.s, lin.Rl, lin.pl, obs.pots[sl], obs.markers[sl], obs.valid[sl])


def _put(st: State, sl: slice, lin) -> None:
    """Write a Linearisation of the frames ``sl`` into the State ``st`` (T frames; its s and poses
    only where ``st`` keeps no linearisation)."""
    st.s[sl], st.Rl[sl], st.pl[sl] = lin.s, lin.Rl, lin.pl
    if st.xi is not None:
        st.xi[:, sl], st.ds_lin[sl] = lin.xi, lin.ds_lin


def _blank(obs: Observation, T: int) -> State:
    """An unfilled State of T frames with room for the linearisation."""
    M, n = obs.n_markers, obs.robot.n_joints
    return State(
        np.empty((T, obs.n_pots)),
        np.empty((T, M, 3, 3)),
        np.empty((T, M, 3)),
        np.empty((6, T, n)),
        np.empty((T, len(obs.linear), len(obs.sparsity.lin_cols))),
    )


def _reusable(out: State | None, st: State | None, T: int) -> bool:
    """Whether ``out`` can hold a q-step's State of T frames: a kept linearisation of T frames,
    not the very State the step starts from."""
    return out is not None and out is not st and out.xi is not None and out.s.shape[0] == T


#: Frames per forward-kinematics pass over the candidates: the kinematics loops over the joints,
#: so its cost per frame falls with the batch, up to a few hundred frames; past a thousand or so
#: (diego) its temporaries, megabytes each, are handed back to the system after each pass and
#: every pass faults in fresh pages. The normal equations' arrays stay in cache at ``batch_size``.
KINEMATICS_BATCH = 500


def kinematics_batch(batch: int) -> int:
    """Frames per forward-kinematics pass where the steps are solved ``batch`` at a time."""
    return max(batch, KINEMATICS_BATCH)


def q_step(
    obs: Observation,
    params: Params,
    noise: Noise,
    q: np.ndarray,
    lam: np.ndarray,
    batch: int = 250,
    jobs: int = 1,
    want_red: bool = True,
    st: State | None = None,
    out: State | None = None,
    trial: np.ndarray | None = None,
):
    """One LM step on every frame.

    Returns (q (T, n), λ (T,), State at the new q (with its linearisation kept), cost (T,),
    redundancy {group: Σ tr_g} at the old q; empty unless ``want_red``: it costs one n x n
    inverse per frame). ``st``: the State at ``q``, whose kept linearisation saves the forward
    kinematics at ``q``. ``out``: a State of the same frames that the caller no longer needs
    (the one before ``st``), overwritten with the new one: a State takes kilobytes per frame
    (diego: 5 kB), and fresh pages for it at every step are system time spent on every step.
    ``trial`` (T,): filled with each frame's cost at its step's candidate, taken or not.

    The steps are solved ``batch`` frames at a time; the candidates' forward kinematics runs
    :data:`KINEMATICS_BATCH` frames at a time, and a frame whose step fails to lower its cost
    (λ x 4, keep q) takes back its row of the State at q.
    """
    T = q.shape[0]
    cand, c0, c1 = np.empty_like(q), np.empty(T), np.empty(T) if trial is None else trial
    base = _blank(obs, T) if st is None or st.xi is None else None  # the linearisation at q
    reds = map_batches(
        lambda sl: _lm_batch(obs, params, noise, q, lam, sl, want_red, st, cand, c0, base), T, batch, jobs
    )
    red = {g: sum(r[g] for r in reds) for g in reds[0]}
    new = out if _reusable(out, st, T) else _blank(obs, T)
    map_batches(lambda sl: _try_batch(obs, params, noise, cand, sl, new, c1), T, kinematics_batch(batch), jobs)
    ok = c1 <= c0  # accept: λ/3; reject: λ x 4, keep q
    lam_out = np.where(ok, np.maximum(lam / 3.0, 1e-7), np.minimum(lam * 4.0, 1e7))
    back = np.flatnonzero(~ok)
    if len(back):
        old = st if base is None else base
        cand[back] = q[back]
        for k in ("s", "Rl", "pl", "ds_lin"):
            getattr(new, k)[back] = getattr(old, k)[back]
        new.xi[:, back] = old.xi[:, back]
    return cand, lam_out, new, np.where(ok, c1, c0), red


def group_rss(obs: Observation, params: Params, st: State) -> dict:
    """{group: (RSS_g, N_g)}: each sensor type's sum of squared residuals (V², m²) at θ and the
    State ``st`` (eq. 2.5, 2.8-2.9), and its number of readings (a marker: three)."""
    out = {}
    rp = params.gain * st.s + params.bias - obs.pots
    for kind in obs.groups:
        if kind == MARKERS:  # a chunk of frames at a time (CHUNK: the temporaries stay small)
            ss = 0.0
            for i in range(0, obs.n_frames, CHUNK):
                sl = slice(i, i + CHUNK)
                xb = base_points(st.Rl[sl], st.pl[sl], params.xyz)
                r = (xb.reshape(-1, 3) @ params.R.T).reshape(xb.shape) + params.T - obs.markers[sl]
                r = r[obs.valid[sl]]
                ss += float(np.sum(r * r))
            out[kind] = (ss, 3 * int(obs.valid.sum()))
        else:
            r = rp[:, obs.kinds == kind]
            out[kind] = (float(np.sum(r * r)), r.size)
    return out


def group_sigma(obs: Observation, params: Params, st: State, used: dict | None = None, rss: dict | None = None) -> dict:
    """Dynamic variance adjustment (§2.3.5): σ_g² = RSS_g / r_g, r_g = N_g − used_g, per sensor
    type, held at the detection limit (:func:`resolvable`) where r_g is too small.

    ``used`` is the degrees of freedom the q-phase took from each type (:func:`redundancy`);
    without it this is the plain RMS residual. ``rss``: :func:`group_rss` at (θ, st) when the
    caller has it.
    """
    used = used or {}
    out = {}
    for kind, (ss, n) in (group_rss(obs, params, st) if rss is None else rss).items():
        dof = max(n - used.get(kind, 0.0), MIN_REDUNDANCY * n)
        out[kind] = float(np.sqrt(ss / dof * floor_factor(n, dof)))
    return out


def resolvable(obs: Observation, used: dict) -> dict:
    """{group: bool}: the group's redundancy r_g = N_g − used_g exceeds √(2 N_g), i.e. its σ is
    estimated from the data, not held at its detection limit (:func:`floor_factor`)."""
    out = {}
    for g in obs.groups:
        n = 3 * int(obs.valid.sum()) if g == MARKERS else obs.n_frames * int(np.sum(obs.kinds == g))
        out[g] = not used or n - used.get(g, 0.0) > np.sqrt(2.0 * n)
    return out


def pot_sigmas(obs: Observation, sigma: dict) -> np.ndarray:
    """σ of each pot from its type's σ: (P,)."""
    return np.array([sigma[k] for k in obs.kinds], dtype=float)
