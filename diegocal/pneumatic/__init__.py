"""Pneumatic valve-chamber models (thesis ch. 4): the 9-parameter model, its fit and prediction.

``terms`` holds the model's terms (c1..c9 of eq. 4.10 as five baseline terms, and the extra terms
``valve_delay``, ``chamber_leak``, ``supply_droop``, ``pressure_offset``); ``params``/``model``
the parametric model of §4.4 built from them; ``fit`` the next-step least squares of §4.5.3;
``predict`` the multi-step prediction of §4.5.4; ``files`` the pneumatic.yaml schema;
``synthetic`` logs made by the model itself. The thin-plate physics of §4.2 is the simulator's
(``diegocal.sim.thin_plate``), never the fit's.
"""

from diegocal.pneumatic.data import ChamberData, chamber_data
from diegocal.pneumatic.fit import BatchFit, ChamberFit, FitOptions, fit_chamber, fit_chambers
from diegocal.pneumatic.model import ChamberModel, steady_state, step
from diegocal.pneumatic.params import C_GAMMA, NAMES, SPECS, ChamberParams
from diegocal.pneumatic.predict import Drift, drift, integrate_from, next_step, predict_with_resets
from diegocal.pneumatic.terms import CAUSES

__all__ = [
    "CAUSES",
    "C_GAMMA",
    "NAMES",
    "SPECS",
    "BatchFit",
    "ChamberData",
    "ChamberFit",
    "ChamberModel",
    "ChamberParams",
    "Drift",
    "FitOptions",
    "chamber_data",
    "drift",
    "fit_chamber",
    "fit_chambers",
    "integrate_from",
    "next_step",
    "predict_with_resets",
    "steady_state",
    "step",
]
