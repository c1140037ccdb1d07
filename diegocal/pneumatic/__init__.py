"""Pneumatic valve-chamber models (thesis ch. 4): the 9-parameter model, its fit and prediction.

``physics`` holds the thin-plate physical model of §4.2 (used by the simulator, never by the fit);
``params``/``model`` the parametric model of §4.4; ``fit`` the next-step least squares of §4.5.3;
``predict`` the multi-step prediction of §4.5.4; ``files`` the pneumatic.yaml schema.
"""

from diegocal.pneumatic.data import ChamberData, chamber_data
from diegocal.pneumatic.fit import BatchFit, ChamberFit, FitOptions, fit_chamber, fit_chambers
from diegocal.pneumatic.model import steady_state, step
from diegocal.pneumatic.params import C_GAMMA, NAMES, SPECS, ChamberParams
from diegocal.pneumatic.predict import Drift, drift, integrate_from, predict_with_resets

__all__ = [
    "C_GAMMA",
    "NAMES",
    "SPECS",
    "BatchFit",
    "ChamberData",
    "ChamberFit",
    "ChamberParams",
    "Drift",
    "FitOptions",
    "chamber_data",
    "drift",
    "fit_chamber",
    "fit_chambers",
    "integrate_from",
    "predict_with_resets",
    "steady_state",
    "step",
]
