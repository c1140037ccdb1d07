"""Calibrate the pots and markers of diego (thesis ch. 2) and predict a held-out session's markers
from its pots alone. Run from the repository's root: python docs/examples/kinematics.py"""

import diegocal.api as dc

log = dc.load_log("sample_data/diego_kinematics.h5")
stac = dc.Stac().fit(log)                                 # the robot the log names; calibration_, q_
print(stac.calibration_.fit.converged, stac.calibration_.sigma_markers)
stac.save("out/diego.calib.yaml", log="sample_data/diego_kinematics.h5")
held = dc.predict("out/diego.calib.yaml", "sample_data/diego_kinematics_heldout.h5")
print(held.title, held.rows)                              # markers from the pots: MAE, m
