"""What every kinematic calibration method returns, and the options they share."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from diegocal.stac.calibration import Calibration


@dataclass(frozen=True)
class IterationRecord:
    """One outer iteration: total cost (negative log-likelihood up to a constant), noise levels, time."""

    iteration: int
    cost: float
    sigma_pots: float
    sigma_markers: float
    seconds: float


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
class StacOptions:
    """Options shared by the calibration methods (each method reads the ones it uses).

    max_iterations : outer alternations (STAC) or passes (EKF)
    tolerance : relative cost change that ends the alternation
    loss : 'linear' (Gaussian, eq. 2.21) or 'huber' (robust to mocap outliers/swapped labels)
    huber_scale : residual (in sigmas) where the Huber loss turns linear
    jobs : worker processes for the per-frame q-phase
    """

    max_iterations: int = 50
    tolerance: float = 1e-6
    loss: str = "linear"
    huber_scale: float = 3.0
    jobs: int = 1
    seed: int = 0
    quiet: bool = True
