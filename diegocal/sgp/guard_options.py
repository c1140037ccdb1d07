"""The SGP guard's options (:class:`Guard`), the limits its choices use, and how the outputs it
took off the joint posterior are predicted (:class:`Stages`) (thesis §3.3; the candidates and the
cross-validated choice are :mod:`diegocal.sgp.guard`). Why each option is on by default and what
it bought is measured in docs/results.md (SGP)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from diegocal.sgp.gp import Hyperparameters
from diegocal.sgp.kernels import REGION_OFF, is_amplitude

#: L-BFGS-B stops when an iteration improves the objective by less than FTOL relative to |f|:
#: scipy's default spends about half of its evaluations on the last 0.1 nat of a likelihood of
#: several thousand nats, for no held-out accuracy (bench/bench_sgp_scale.py).
FTOL = 1e-6
#: The stretches along the σ_z-ℓ ridge tried by Guard.extend_capped.
STRETCHES = 2.0 ** np.arange(1, 11)
#: An input is "linear in the parametric part" when its column is in the span of the output's
#: feature columns and a constant to this relative residual (rounding only: an exact column).
LINEAR_TOLERANCE = 1e-6
#: Two stages must also beat the guard's other choice by this fraction of its cross-validated
#: nMSE: a smaller win is a rounding-level difference a machine could flip.
MIN_TWO_STAGE_GAIN = 1e-3
#: A GP (joint, or two stages where the guard's other choice is PR) must also beat PR by this
#: fraction of PR's cross-validated nMSE: GPs kept where nothing is unmodelled won the
#: cross-validation by less and let W drift (bench/bench_sgp_sizes.py).
MIN_GP_GAIN = 0.02
#: The joint candidates' cross-validation is repeated with each fold's hyperparameters re-learnt
#: (GuardCandidates._joint_nested) when it has at most this many samples.
NESTED_JOINT_MAX = 500
#: The two-stage GP's amplitude above a cut kernel's onset, at most this many times the residual's
#: std there (capped_above).
MAX_AMPLITUDE_ABOVE = 4.0


def capped_above(kernel, theta: np.ndarray, est, U: np.ndarray, res: np.ndarray) -> np.ndarray:
    """``theta`` of a GP on PR's residual ``res`` (N,) with the amplitude of a cut kernel's side
    above its onset, r·σ_z (:class:`~diegocal.sgp.kernels.Region`), held to at most
    MAX_AMPLITUDE_ABOVE times the residual's std over the training samples above the onset
    (``est``'s input scaling; U (N, p) raw). Unchanged for a kernel that is not cut.

    Why: the joint GP's σ_z is capped at twice the parametric residual (Guard.max_amplitude), the
    two-stage GP's side above the onset was not; on a short run ML-II put it at tens of times the
    residual there and it extrapolated metres of torque where a test left the training range
    (tests/sgp/test_two_stage_amplitude.py)."""
    names = getattr(kernel, "names", ())
    if len(theta) == 0 or "region_onset" not in names or theta[0] >= REGION_OFF:
        return theta
    dim = kernel.dim
    above = (U[:, dim] - est.u_mean_[dim]) / est.u_std_[dim] >= theta[0]
    if above.sum() < 2:
        return theta
    amp = [i for i, n in enumerate(names) if is_amplitude(n)][0]
    ratio = names.index("log_region_ratio")
    out = np.array(theta, float, copy=True)
    out[ratio] = min(out[ratio], np.log(MAX_AMPLITUDE_ABOVE * res[above].std()) - out[amp])
    return out


@dataclass(frozen=True)
class Guard:
    """Guards against the GP part soaking up physics the parametric part explains (all optional).

    Why it is needed: wherever a parametric term is a smooth function of the GP's inputs (gravity
    in q, friction in qd) the GP can carry part of it at nearly the same marginal likelihood, and
    along a trajectory every smooth function of time is a function of the state, so a flexible GP
    can even mimic terms in inputs it does not see. In-sample this costs nothing; far from the
    data, where the GP reverts to its prior, the W it distorted predicts alone.
    :data:`diegocal.sgp.DEFAULT_GUARD` is the default setting.

    Attributes
    ----------
    max_lengthscale : float or None
        Upper bound on every length-scale, in units of the input's training std: the GP reverts
        to its prior a few stds outside the data instead of extrapolating a trend, and cannot
        become a global smooth function competing with W.
    lengthscale_prior : (mean, std) or None
        Gaussian prior on log ℓ (ℓ in units of the input's std): MAP instead of ML-II.
    amplitude_prior : float or None
        Std of a Gaussian prior on log(σ_z / s), s the std of the parametric-only fit's residual.
    validation_fraction : float
        Size of the contiguous blocks (fraction of the samples, in time order) of a blocked
        cross-validation that chooses, per output, among the candidates below and a
        parametric-only fallback (PR): a GP is kept only where it lowers the cross-validated
        nMSE by more than one standard error and MIN_GP_GAIN of PR's. Each block is predicted
        by the posterior of the others; a winner is confirmed with each fold's hyperparameters
        re-learnt without its block (nested; the joint GPs only on small cross-validations).
    restarts : int
        Extra starts on top of the estimator's ``restarts``.
    fix_sigma_w : bool
        Keep σ_w at a large value (a flat prior on W) instead of learning it by ML-II.
    max_amplitude : float or None
        Upper bound on σ_z in units of the parametric-only fit's residual std: Z models the
        *deviations* from the parametric model (thesis §3.3), not the physics.
    release_capped : bool
        A candidate in which every input whose length-scale ends at the cap is *released* (ℓ
        fixed at RELEASED_LENGTHSCALE stds: the GP constant along it): ARD's verdict "no
        structure at any scale the cap allows" then holds outside the data too, so an irrelevant
        input that drifts (a wheel's angle) does not make the GP revert and drop what it models.
    extend_capped : bool
        A candidate where the likelihood, not the cap, decides the limit of each capped
        length-scale (:meth:`GuardCandidates._extend`): an SE kernel carries a linear trend
        (viscous friction in a velocity) only near its linear limit, which the σ_z cap stops.
        For parametric models without a viscous friction column only.
    two_stage : bool
        A candidate of two stages (thesis §3.4.1: W fixed at PR's posterior, then a capped GP on
        PR's residual); the outputs that choose it or the parametric fallback are predicted by
        those stages (:class:`Stages`), so that an output that falls back *is* PR whatever the
        other outputs' GPs do to the shared W.
    region : bool
        With ``two_stage``: each output's GP on PR's residual may be cut at an onset in its
        joint's angle (:class:`~diegocal.sgp.kernels.Region`, friction confined to part of the
        range), judged on folds of every sample outside each block against PR.
    joint_region : bool
        With ``region``: where the cut two stages lose the choice, a joint GP cut at the same
        onset (on a short run PR's friction parameters are biased by the samples above the
        onset, which no GP on PR's residual mends, while the joint GP carries the step).
    """

    max_lengthscale: float | None = None
    lengthscale_prior: tuple[float, float] | None = None
    amplitude_prior: float | None = None
    validation_fraction: float = 0.0
    restarts: int = 0
    fix_sigma_w: bool = False
    max_amplitude: float | None = None
    release_capped: bool = False
    extend_capped: bool = False
    two_stage: bool = False
    region: bool = False
    joint_region: bool = False


#: The candidates whose outputs are predicted by the joint posterior (W shared with the GPs).
JOINT = ("learnt", "released", "extended", "cut")
TWO_STAGE, PARAMETRIC = "two-stage", "parametric"


@dataclass(frozen=True)
class Stages:
    """How the outputs the guard took off the joint posterior are predicted (Guard.two_stage).

    Attributes
    ----------
    selection : tuple of str, the guard's choice per output (JOINT, TWO_STAGE or PARAMETRIC)
    pr : Hyperparameters, PR's (σ_w, σ_v per output; no kernel parameters)
    residual : Hyperparameters or None, the GPs on PR's residual (the estimator's kernels),
        learnt for every output; used by the TWO_STAGE ones
    """

    selection: tuple
    pr: Hyperparameters
    residual: Hyperparameters | None = None

    def mode(self, j: int) -> str:
        """ "joint", TWO_STAGE or PARAMETRIC: what predicts output ``j``."""
        return "joint" if self.selection[j] in JOINT else self.selection[j]
