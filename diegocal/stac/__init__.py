"""STAC: simultaneous tracking and calibration (thesis ch. 2), with classical and EKF baselines.

Public surface: :func:`calibrate` (STAC, §2.2-2.3), :func:`predict` (cross-sensor prediction
on novel data, §2.7.2), the calib.yaml schema :class:`Calibration` and the shared
:class:`StacOptions` / :class:`StacResult`.
"""

from diegocal.stac.calibration import Calibration, FitInfo
from diegocal.stac.predict import Prediction, predict
from diegocal.stac.result import IterationRecord, StacOptions, StacResult
from diegocal.stac.stac import calibrate

__all__ = [
    "Calibration",
    "FitInfo",
    "IterationRecord",
    "Prediction",
    "StacOptions",
    "StacResult",
    "calibrate",
    "predict",
]
