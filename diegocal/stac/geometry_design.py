"""Which static poses to record: D-optimal selection from a candidate set (issue #34).

A pose k contributes J_kᵀ J_k to the information matrix of the identifiable parameters of the
geometry fit (:mod:`diegocal.stac.geometry`; J_k the (3M, p) Jacobian of its markers, unit noise:
the mocap frame's rotation leaves JᵀJ unchanged, so the frame's start does not matter). D-optimal
design maximises log det Σ_k J_kᵀ J_k, the (negative) log volume of the parameters' confidence
ellipsoid. :func:`select_poses` adds poses greedily, each the candidate of largest gain

    log det(A + J_kᵀ J_k) − log det A = log det(I + J_k A⁻¹ J_kᵀ)

(A = the poses already chosen, or already recorded, plus a ridge of 1e-9 × its trace so that the
first few are chosen before A is full rank), as FIGAROH's optimal-configuration tool picks its
poses. The identifiable set is that of all candidates together (:func:`identifiable`).
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


@dataclass(frozen=True)
class PoseDesign:
    """Per-candidate information of the identifiable parameters.

    rows : (K, 3M, p') Jacobian of each candidate's markers with respect to the identifiable
        parameters, each column scaled by its RMS over the candidates (D-optimality does not
        depend on the scaling; it keeps the ridge and the condition number meaningful)
    names : (p',) the parameters
    """

    rows: np.ndarray
    names: tuple[str, ...]

    def information(self, index) -> np.ndarray:
        """Σ J_kᵀ J_k (p', p') over the candidates ``index``."""
        J = self.rows[np.asarray(index, int)].reshape(-1, self.rows.shape[-1])
        return J.T @ J

    def log_det(self, index) -> float:
        """log det of the information of ``index`` (−inf when it does not determine every parameter)."""
        sign, value = np.linalg.slogdet(self.information(index))
        return float(value) if sign > 0 else -np.inf

    def stderr(self, index, sigma: float = 1.0) -> np.ndarray:
        """Standard errors (p',) of the (scaled) parameters from the poses ``index`` at noise σ."""
        return sigma * np.sqrt(np.diag(np.linalg.pinv(self.information(index))))


def pose_design(robot: Robot, cal: Calibration, q: np.ndarray) -> PoseDesign:
    """The design of candidate joint angles q (K, n) rad for ``robot`` with calibration ``cal``
    (its pots' gains and biases, markers; its geometry terms are not applied: the nominal model)."""
    q = robot.check_q(q)
    lay = layout(robot, cal)
    state = start_state(robot, cal, lay)
    pots = np.zeros((q.shape[0], len(cal.pot_names)))
    pots[:, lay.pots] = q[:, lay.joints] * state.gain[lay.pots] + state.bias[lay.pots]
    _, J, _ = observe(robot, lay, state, cal.marker_links, pots)
    K, M = J.shape[0], J.shape[1]
    flat = J.reshape(K * M * 3, -1)
    ident = identifiable(flat, lay.group)
    if not ident.kept.any():
        raise FitError("no geometric parameter moves a marker at these candidate poses")
    rows = J[..., ident.kept].reshape(K, M * 3, -1)
    scale = np.sqrt(np.mean(rows.reshape(-1, rows.shape[-1]) ** 2, axis=0))
    names = tuple(n for n, k in zip(lay.names, ident.kept, strict=True) if k)
    return PoseDesign(rows / np.where(scale > 0, scale, 1.0), names)


def select_poses(design: PoseDesign, n: int, recorded=()) -> np.ndarray:
    """Indices (n,) of the candidates to record next, greedily D-optimal (module docstring), given
    the candidates already ``recorded`` (indices into the same design)."""
    K = design.rows.shape[0]
    recorded = [int(i) for i in recorded]
    free = np.setdiff1d(np.arange(K), recorded)
    if n < 1 or n > len(free):
        raise FitError(f"cannot choose {n} poses from {len(free)} candidates not yet recorded")
    A = design.information(recorded) if recorded else np.zeros((design.rows.shape[-1],) * 2)
    ridge = RIDGE * max(np.trace(design.information(np.arange(K))) / A.shape[0], 1e-300)
    chosen = []
    for _ in range(n):
        Ainv = np.linalg.inv(A + ridge * np.eye(A.shape[0]))
        G = design.rows[free]
        # log det(I + J_k A⁻¹ J_kᵀ) for every free candidate at once
        S = np.einsum("kip,pq,kjq->kij", G, Ainv, G) + np.eye(G.shape[1])
        gain = np.linalg.slogdet(S)[1]
        best = int(np.argmax(gain))
        chosen.append(int(free[best]))
        A = A + G[best].T @ G[best]
        free = np.delete(free, best)
    return np.array(chosen)
