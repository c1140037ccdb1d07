"""Fit the 3-link arm's torques with the semi-parametric GP (thesis ch. 3) and predict another
session with ±2σ. Run from the repository's root: python docs/examples/dynamics.py"""

import diegocal.api as dc
from diegocal.sgp import SGPOptions

sgp = dc.SGP(SGPOptions(kind="sgp")).fit("sample_data/arm3_dynamics.h5")   # kind: pr | gp | prgp | sgp
print(sgp.model_.parametric_.names[:3], sgp.model_.hyperparameters_["joint3"].get("guard_choice"))
pred = sgp.predict("sample_data/arm3_hidden_friction.h5")                   # tau, tau_std (T, 3) N·m
print(pred.tau.shape, float(pred.tau_std.mean()))
sgp.save("out/arm3.sgp", log="sample_data/arm3_dynamics.h5")
print(dc.predict("out/arm3.sgp", "sample_data/arm3_hidden_friction.h5").rows[:4])
