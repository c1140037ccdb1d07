"""What the arm's model gets wrong, named, with the extended model and its held-out gain; then
the extended model used on the log. Run from the repository's root: python docs/examples/diagnose.py"""

import diegocal.api as dc

log = dc.load_log("sample_data/arm3_hidden_friction.h5")
found = dc.diagnose(log, domain="dynamics")["dynamics"]
for f in found.findings:                                  # most held-out error removed first
    print(f.term.label, f.gain())
found.save("out/arm3.diagnosis.yaml", log="sample_data/arm3_hidden_friction.h5")
print(dc.predict("out/arm3.diagnosis.yaml", "sample_data/arm3_hidden_friction.h5").rows[-3:])
