"""STAC: simultaneous tracking and calibration (thesis ch. 2), with classical and EKF baselines."""

from diegocal.stac.calibration import Calibration, FitInfo

__all__ = ["Calibration", "FitInfo"]
