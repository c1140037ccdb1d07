"""The alternatives to STAC's default schedule (:mod:`.stac`): Anderson acceleration of the
alternation, and the thesis's "BFGS" q-phase (§2.6.1)."""

from __future__ import annotations

import numpy as np
from scipy.optimize import minimize

from diegocal.stac.model import Observation
from diegocal.stac.qphase import normal_equations
from diegocal.stac.result import StacOptions


class Anderson:
    """Anderson acceleration (type II, depth m) of the fixed-point map q -> G(q).

    One STAC alternation is a contraction whose rate is slow along the directions where q and
    θ co-move (a pot's gain against the joint angles it reads): plain alternation needed
    hundreds of iterations on the test robots. Mixing the last m iterates,
    q⁺ = G(q_k) − ΔG γ with γ = argmin ‖f_k − ΔF γ‖ (f = G(q) − q), extrapolates along them; the
    caller keeps the mixed iterate only when it lowers the cost (else restarts the history).
    """

    def __init__(self, depth: int = 5):
        self.depth = depth
        self.reset()

    def reset(self) -> None:
        self.g, self.f = [], []

    def mix(self, q: np.ndarray, gq: np.ndarray) -> np.ndarray | None:
        self.g.append(gq.ravel().copy())
        self.f.append((gq - q).ravel())
        if len(self.g) > self.depth + 1:
            self.g.pop(0)
            self.f.pop(0)
        if len(self.g) < 2:
            return None
        dF = np.stack([self.f[i + 1] - self.f[i] for i in range(len(self.f) - 1)], axis=1)
        dG = np.stack([self.g[i + 1] - self.g[i] for i in range(len(self.g) - 1)], axis=1)
        gamma = np.linalg.lstsq(dF, self.f[-1], rcond=1e-10)[0]
        return (self.g[-1] - dG @ gamma).reshape(gq.shape)


class BfgsSchedule:
    """Thesis §2.6.1 'BFGS': quasi-Newton steps on all q with θ re-solved before each gradient.

    Each outer iteration runs a few L-BFGS-B iterations (bounds = joint limits) on
    f(q) = Σ_t cost_t(q_t; θ, σ) with θ, σ those of the last p-phase; the gradient is the exact
    per-frame JᵀW r of the q-phase.
    """

    def __init__(self, obs: Observation, options: StacOptions, inner: int = 3):
        self.obs, self.options, self.inner = obs, options, inner

    def step(self, q, params, noise):
        obs, T, n = self.obs, self.obs.n_frames, self.obs.robot.n_joints
        bounds = list(zip(np.tile(obs.lower, T), np.tile(obs.upper, T), strict=True))

        def parts(x):
            return [
                normal_equations(obs, params, noise, x.reshape(T, n), slice(i, i + self.options.batch_size))
                for i in range(0, T, self.options.batch_size)
            ]

        def f(x):
            ps = parts(x)
            return float(sum(p[2].sum() for p in ps)), np.concatenate([p[1] for p in ps]).ravel()

        res = minimize(
            f,
            q.ravel(),
            jac=True,
            method="L-BFGS-B",
            bounds=bounds,
            options={"maxiter": self.inner},
        )
        ps = parts(res.x)
        used = {g: sum(p[4][g] for p in ps) for g in ps[0][4]}
        q = res.x.reshape(T, n)
        return q, obs.state(q, self.options.batch_size), used
