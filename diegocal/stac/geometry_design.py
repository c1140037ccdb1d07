"""Which static poses to record: optimal selection from a candidate set (issue #34).

A pose k contributes J_kᵀ C_k⁻¹ J_k to the information matrix A of the identifiable parameters of
the geometry fit (:mod:`diegocal.stac.geometry`: the mocap frame, the markers, the pots' zeros and
gains and the link geometry, all fitted together; J_k the (3M, p) Jacobian of its markers, C_k the
fit's noise model ``σ_m² I + s² J_q,k diag(1/gain²) J_q,kᵀ`` relative to σ_m²; the mocap frame's
rotation leaves A unchanged, so the frame's start does not matter). Two criteria:

- ``"I"`` (I- or V-optimal, the default): minimise the mean variance of the markers' predictions
  over the candidate poses, ``tr(W A⁻¹)`` with ``W = mean_k J_kᵀ J_k / 3M``, in units of σ_m². This
  is what a held-out pose's error over the noise floor judges (its excess is the prediction's
  error ``J_t (θ̂ − θ)``), and it is in metres whatever mix of metres and radians θ holds;
- ``"D"``: maximise ``log det A`` (the parameters' confidence ellipsoid), FIGAROH's criterion.

:func:`select_poses` adds poses greedily, each the candidate of largest gain (D-optimal while A
is rank-deficient, so that the first poses make every parameter determined: the gain
``log det(I + G A⁻¹ Gᵀ)`` with A ridged by RIDGE × its mean diagonal; then the criterion's:
``tr((I + G A⁻¹ Gᵀ)⁻¹ G A⁻¹ W A⁻¹ Gᵀ)`` for I, by the Woodbury identity), then exchanges
(Fedorov): each chosen pose in turn is swapped for the candidate that most improves the criterion
until a pass changes nothing. Greedy choices alone leave the early, rank-filling poses in the set;
the exchange replaces them. The chosen set is finally ordered greedily within itself, so that the
first poses of the list are already a good design (a lab that stops early loses least).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from diegocal.errors import FitError
from diegocal.robot import Robot
from diegocal.stac.calibration import Calibration
from diegocal.stac.geometry import identifiable, start_state
from diegocal.stac.geometry_model import layout, observe

#: Ridge of the information matrix while it is rank-deficient (relative to its mean diagonal).
RIDGE = 1e-9
#: The criteria :func:`select_poses` knows.
CRITERIA = ("I", "D")
#: Exchange passes at most; a swap must improve the criterion by this fraction to count.
EXCHANGE_PASSES, EXCHANGE_TOL = 20, 1e-6


@dataclass(frozen=True)
class PoseDesign:
    """Per-candidate information of the identifiable parameters.

    rows : (K, 3M, p') Jacobian of each candidate's markers with respect to the identifiable
        parameters, whitened by the noise model relative to σ_m (module docstring), each column
        scaled by its RMS over the candidates (no criterion depends on the scaling; it keeps the
        ridge and the condition number meaningful)
    target : (p', p') W, the mean over candidates and marker coordinates of JᵀJ (unwhitened): the
        prediction variance of a marker coordinate at a candidate, averaged, is tr(W A⁻¹)
    names : (p',) the parameters
    """

    rows: np.ndarray
    target: np.ndarray
    names: tuple[str, ...]

    def information(self, index) -> np.ndarray:
        """A = Σ J_kᵀ C_k⁻¹ J_k (p', p') over the candidates ``index``."""
        J = self.rows[np.asarray(index, int)].reshape(-1, self.rows.shape[-1])
        return J.T @ J

    def log_det(self, index) -> float:
        """log det of the information of ``index`` (−inf when it does not determine every parameter)."""
        sign, value = np.linalg.slogdet(self.information(index))
        return float(value) if sign > 0 else -np.inf

    def stderr(self, index, sigma: float = 1.0) -> np.ndarray:
        """Standard errors (p',) of the (scaled) parameters from the poses ``index`` at noise σ."""
        return sigma * np.sqrt(np.diag(np.linalg.pinv(self.information(index))))

    def prediction_variance(self, index) -> float:
        """Mean variance of a marker coordinate's prediction over the candidates, tr(W A⁻¹), in
        units of σ_m² (inf when the poses ``index`` do not determine every parameter)."""
        A = self.information(index)
        if np.linalg.matrix_rank(A) < A.shape[0]:
            return np.inf
        return float(np.trace(np.linalg.solve(A, self.target)))

    def score(self, index, criterion: str) -> float:
        """The criterion of ``index``, smaller better: tr(W A⁻¹) for I, −log det A for D."""
        return self.prediction_variance(index) if criterion == "I" else -self.log_det(index)


def pose_design(
    robot: Robot, cal: Calibration, q: np.ndarray, sigma_markers: float | None = None, sigma_pots: float | None = None
) -> PoseDesign:
    """The design of candidate joint angles q (K, n) rad for ``robot`` with calibration ``cal``
    (its pots' gains and biases, markers; its geometry terms are not applied: the nominal model).
    The noise model is σ_m = ``sigma_markers`` (m) and s = ``sigma_pots`` (pot unit), by default the
    calibration's (a STAC calibration's); without both, markers only (unit weights)."""
    q = robot.check_q(q)
    lay = layout(robot, cal)
    state = start_state(robot, cal, lay)
    pots = np.zeros((q.shape[0], len(cal.pot_names)))
    pots[:, lay.pots] = q[:, lay.joints] * state.gain[lay.pots] + state.bias[lay.pots]
    _, J, Jq = observe(robot, lay, state, cal.marker_links, pots)
    K, M = J.shape[0], J.shape[1]
    ident = identifiable(J.reshape(K * M * 3, -1), lay.group)
    if not ident.kept.any():
        raise FitError("no geometric parameter moves a marker at these candidate poses")
    rows = J[..., ident.kept].reshape(K, M * 3, -1)
    scale = np.sqrt(np.mean(rows.reshape(-1, rows.shape[-1]) ** 2, axis=0))
    rows = rows / np.where(scale > 0, scale, 1.0)
    flat = rows.reshape(-1, rows.shape[-1])
    target = flat.T @ flat / flat.shape[0]
    sm = cal.sigma_markers if sigma_markers is None else sigma_markers
    sp = cal.sigma_pots if sigma_pots is None else sigma_pots
    if np.isfinite(sm) and np.isfinite(sp) and sm > 0 and sp > 0:
        # C_k / σ_m² = I + (s/σ_m)² J_q diag(1/gain²) J_qᵀ (geometry.py's noise model), whitened by its Cholesky
        Aq = Jq[..., lay.joints].reshape(K, M * 3, -1) / state.gain[lay.pots]
        C = np.eye(M * 3) + (sp / sm) ** 2 * np.einsum("kij,klj->kil", Aq, Aq)
        rows = np.linalg.solve(np.linalg.cholesky(C), rows)
    names = tuple(n for n, k in zip(lay.names, ident.kept, strict=True) if k)
    return PoseDesign(rows, target, names)


def select_poses(design: PoseDesign, n: int, recorded=(), criterion: str = "I", exchange: bool = True) -> np.ndarray:
    """Indices (n,) of the candidates to record next, given the candidates already ``recorded``
    (indices into the same design): greedy, then (``exchange``) Fedorov exchanges, by
    ``criterion`` "I" (mean prediction variance) or "D" (log det); module docstring."""
    if criterion not in CRITERIA:
        raise FitError(f"unknown pose criterion {criterion!r}; expected one of {', '.join(CRITERIA)}")
    K, p = design.rows.shape[0], design.rows.shape[-1]
    recorded = [int(i) for i in recorded]
    free = np.setdiff1d(np.arange(K), recorded)
    if n < 1 or n > len(free):
        raise FitError(f"cannot choose {n} poses from {len(free)} candidates not yet recorded")
    base = design.information(recorded) if recorded else np.zeros((p, p))
    ridge = RIDGE * max(np.trace(design.information(np.arange(K))) / p, 1e-300) * np.eye(p)
    chosen = _greedy(design, base, ridge, free, n, criterion)
    if exchange:
        chosen = _exchange(design, base, ridge, chosen, free, criterion)
        chosen = _greedy(design, base, ridge, np.array(chosen), n, criterion)  # the order: best prefixes first
    return np.array(chosen, int)


def _gains(design: PoseDesign, A: np.ndarray, ridge: np.ndarray, index: np.ndarray, criterion: str) -> np.ndarray:
    """Each candidate of ``index``'s gain when added to information A (larger better)."""
    p = A.shape[0]
    full = criterion == "I" and np.linalg.matrix_rank(A, tol=1e-8 * max(np.trace(A) / p, 1e-300)) == p
    Ainv = np.linalg.inv(A + (0 if full else ridge))
    G = design.rows[index]
    Gt = G.transpose(0, 2, 1)
    S = G @ Ainv @ Gt + np.eye(G.shape[1])
    if not full:  # log det(I + G A⁻¹ Gᵀ): D-optimal, and I's rank-filling start
        return np.linalg.slogdet(S)[1]
    T = G @ (Ainv @ design.target @ Ainv) @ Gt
    return np.trace(np.linalg.solve(S, T), axis1=1, axis2=2)  # Woodbury: the drop of tr(W A⁻¹)


def _greedy(design, base, ridge, pool, n, criterion) -> list[int]:
    """n candidates of ``pool`` added one at a time, each of largest gain."""
    A, pool, out = base.copy(), np.asarray(pool, int), []
    for _ in range(n):
        best = int(np.argmax(_gains(design, A, ridge, pool, criterion)))
        out.append(int(pool[best]))
        A = A + design.rows[pool[best]].T @ design.rows[pool[best]]
        pool = np.delete(pool, best)
    return out


def _exchange(design, base, ridge, chosen, free, criterion) -> list[int]:
    """Fedorov exchange: each chosen pose swapped for the candidate of ``free`` that most improves
    the criterion, pass after pass, until a pass swaps nothing."""
    chosen = list(chosen)
    for _ in range(EXCHANGE_PASSES):
        swapped = False
        for i in range(len(chosen)):
            rest = chosen[:i] + chosen[i + 1 :]
            A = base + design.information(rest) if rest else base.copy()
            pool = free[~np.isin(free, rest)]
            gain = _gains(design, A, ridge, pool, criterion)
            mine = gain[np.flatnonzero(pool == chosen[i])[0]]
            best = int(np.argmax(gain))
            if gain[best] > mine + EXCHANGE_TOL * max(abs(mine), 1e-300) and pool[best] != chosen[i]:
                chosen[i] = int(pool[best])
                swapped = True
        if not swapped:
            break
    return chosen
