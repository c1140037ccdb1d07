"""STAC: simultaneous tracking and calibration (thesis ch. 2), with classical and EKF baselines."""

from diegocal.stac.calibration import Calibration, FitInfo
from diegocal.stac.result import IterationRecord, StacOptions, StacResult

__all__ = ["Calibration", "FitInfo", "IterationRecord", "StacOptions", "StacResult"]
