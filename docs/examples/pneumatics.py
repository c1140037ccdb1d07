"""Fit the 9-parameter valve-chamber model (thesis ch. 4) of two of diego's chambers and predict
their pressure open loop. Run from the repository's root: python docs/examples/pneumatics.py"""

import diegocal.api as dc

fit = dc.Pneumatic(chambers=("r_elbow.flex", "r_elbow.ext")).fit("sample_data/diego_pneumatics.h5")
for name, chamber in fit.fits_.items():
    print(name, chamber.params.values["c1"], chamber.drift_2s)   # valve origin (V), 2-s drift
fit.save("out/elbow.pneumatic.yaml", log="sample_data/diego_pneumatics.h5")
print(dc.predict("out/elbow.pneumatic.yaml", "sample_data/diego_pneumatics.h5").rows)
