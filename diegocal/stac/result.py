"""What every kinematic calibration method returns, and the options they share."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from diegocal.stac.calibration import Calibration

#: Safety cap on STAC's alternations per stage: the fit stops at its tolerance, normally within a
#: few tens of iterations; one that reaches the cap is returned with ``converged`` False.
MAX_ITERATIONS = 500


@dataclass(frozen=True)
class IterationRecord:
    """One outer iteration: cost (negative log-likelihood up to a constant), noise levels, time
    since the start, and the number of frames it used (the coarse stage uses a subset)."""

    iteration: int
    cost: float
    sigma_pots: float
    sigma_markers: float
    seconds: float
    frames: int = 0


@dataclass(frozen=True)
class StacResult:
    """A calibration and the joint angles tracked with it.

    Attributes
    ----------
    calibration : Calibration
    q : ndarray of shape (T, n), rad; tracked joint angles in the robot's joint order
    history : tuple of IterationRecord, one per outer iteration
    """

    calibration: Calibration
    q: np.ndarray
    history: tuple[IterationRecord, ...] = ()


@dataclass(frozen=True)
class WarmStart:
    """Where a fit of nearly the same model ended, for STAC to start from instead of the nominal θ
    and its coarse stage: its calibration (θ and σ per sensor type) and q (T, n) rad on the log's
    frames (a diagnosis refits its extended model after each small step of a term)."""

    calibration: Calibration
    q: np.ndarray


@dataclass(frozen=True)
class StacOptions:
    """Options shared by the calibration methods (each method reads the ones it uses).

    max_iterations : safety cap on the outer alternations (STAC: per stage, coarse and full-data;
        the fit ends at ``tolerance``, :data:`MAX_ITERATIONS`) or on the classical fit's steps
    tolerance : cost change per reading (x 10, nats) that ends the alternation (STAC: once σ
        has settled too)
    loss : 'linear' (Gaussian, eq. 2.21), or for the markers 'huber' or 'tukey' (Tukey's biweight
        after a Huber stage), robust to mocap outliers and swapped labels (:mod:`.robust`)
    huber_scale : residual (in sigmas) where the Huber loss turns linear
    jobs : workers (STAC: threads over batches of frames in the q-phase and the joint step)
    schedule : STAC q-phase schedule, 'lm-iter' (default), 'lm-batch' or 'bfgs' (thesis §2.6.1)
    q_steps : LM steps per alternation in 'lm-iter'
    batch_size : frames per batched normal-equation solve
    coarse_frames : STAC first converges on an evenly spaced subset of about this many frames
        when the log has more, then finishes on all frames (0: all frames throughout)
    marker_seed : 'origin' (markers start at their link origins, §2.7.1) or 'nominal' (sensors.yaml)
    joint : try a joint Gauss-Newton step on (q, pot gains/biases) each iteration (joint_step.py)
    anderson : depth of the Anderson acceleration of the alternation (0 = plain alternation)
    check_poses : STAC on a static-pose log writes off the poses whose markers disagree with their
        pots beyond the other poses' noise, and refits (:mod:`.poses`)
    on_iteration : optional callback(iteration, Calibration) after each outer iteration (benchmarks)
    """

    max_iterations: int = MAX_ITERATIONS
    tolerance: float = 1e-6
    loss: str = "linear"
    huber_scale: float = 3.0
    jobs: int = 1
    seed: int = 0
    quiet: bool = True
    schedule: str = "lm-iter"
    q_steps: int = 1
    batch_size: int = 250
    coarse_frames: int = 2500
    marker_seed: str = "origin"
    anderson: int = 0
    joint: bool = True
    check_poses: bool = True
    on_iteration: Callable | None = None
