"""STAC: simultaneous tracking and calibration (thesis ch. 2), with classical and EKF baselines.

Public surface: :func:`calibrate` (STAC, §2.2-2.3), :func:`predict` (cross-sensor prediction
on novel data, §2.7.2), the baselines :func:`calibrate_classical` (σp = 0, eq. 2.28-2.29)
and :func:`calibrate_ekf` (eq. 2.24-2.27), the calib.yaml schema :class:`Calibration` and the shared
:class:`StacOptions` / :class:`StacResult`.
"""

from diegocal.stac.calibration import Calibration, FitInfo
from diegocal.stac.classical import calibrate_classical
from diegocal.stac.ekf import EkfOptions, calibrate_ekf
from diegocal.stac.predict import Prediction, predict
from diegocal.stac.result import IterationRecord, StacOptions, StacResult
from diegocal.stac.stac import calibrate

__all__ = [
    "Calibration",
    "EkfOptions",
    "FitInfo",
    "IterationRecord",
    "Prediction",
    "StacOptions",
    "StacResult",
    "calibrate",
    "calibrate_classical",
    "calibrate_ekf",
    "predict",
]
