"""Fit the 3-link arm's torques with the semi-parametric GP (thesis ch. 3) and predict another
session of the same robot (the Makefile's held-out session) with ±2σ. Run from the repository's
root: python docs/examples/dynamics.py"""

import numpy as np

import diegocal.api as dc
from diegocal.io import save_log
from diegocal.sgp import SGPOptions
from diegocal.sim.dynamics import DynamicsOptions, simulate_dynamics

sgp = dc.SGP(SGPOptions(kind="sgp")).fit("sample_data/arm3_dynamics.h5")   # kind: pr | gp | prgp | sgp
print(sgp.model_.parametric_.names[:3], sgp.model_.hyperparameters_["joint3"].get("guard_choice"))
# the same robot (robot_seed 1, the sample log's seed), another trajectory and noise (seed 2)
session = DynamicsOptions(duration=8, rate_hz=50, trajectory="figure8-horizontal", robot_seed=1,
                          effects=("position_friction:joint3",), regions={"joint3": (1.3, 1.6)})
save_log(simulate_dynamics(dc.load_robot("robots/arm3"), session, np.random.default_rng(2)), "out/arm3_heldout.h5")
pred = sgp.predict("out/arm3_heldout.h5")                                   # tau, tau_std (T, 3) N·m
print(pred.tau.shape, float(pred.tau_std.mean()))
sgp.save("out/arm3.sgp", log="sample_data/arm3_dynamics.h5")
print(dc.predict("out/arm3.sgp", "out/arm3_heldout.h5").rows[:4])
