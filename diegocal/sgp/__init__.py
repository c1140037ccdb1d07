"""Semi-parametric Gaussian processes for robot dynamics (thesis ch. 3).

Public API::

    from diegocal.sgp import fit_dynamics, load_model, SGPOptions, TorquePrediction
    model = fit_dynamics(log, robot, SGPOptions(kind="sgp"))   # "pr" | "gp" | "prgp" | "sgp"
    pred = model.predict(log)            # TorquePrediction: tau, tau_std (T, n)
    save_model(model, "logs.sgp/"); load_model("logs.sgp/")

Lower level: :class:`SemiParametricGP` on plain arrays (any features), kernels in
:mod:`diegocal.sgp.kernels`, the torque regressor and base parameters in
:mod:`diegocal.sgp.regressor`.
"""

from diegocal.sgp.estimator import Guard, SemiParametricGP, Stages
from diegocal.sgp.gp import Hyperparameters
from diegocal.sgp.kernels import Constant, Kernel, SquaredExponential, Subspace
from diegocal.sgp.model import (
    DEFAULT_GUARD,
    KINDS,
    DynamicsModel,
    ParametricEstimate,
    SGPOptions,
    TorquePrediction,
    fit_dynamics,
    nmse,
)
from diegocal.sgp.regressor import BaseParameters, base_parameters, full_regressor, true_parameters
from diegocal.sgp.store import is_model_dir, load_model, load_summary, save_model

__all__ = [
    "DEFAULT_GUARD",
    "KINDS",
    "BaseParameters",
    "Constant",
    "DynamicsModel",
    "Guard",
    "Hyperparameters",
    "Kernel",
    "ParametricEstimate",
    "SGPOptions",
    "SemiParametricGP",
    "SquaredExponential",
    "Stages",
    "Subspace",
    "TorquePrediction",
    "base_parameters",
    "fit_dynamics",
    "full_regressor",
    "is_model_dir",
    "load_model",
    "load_summary",
    "nmse",
    "save_model",
    "true_parameters",
]
