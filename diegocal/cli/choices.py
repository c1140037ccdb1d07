"""The words and defaults the options name, without importing the library that owns them.

`--help` must not import numpy, scipy or the fitting code (STYLE.md), yet the option help and
the parse-time checks need the library's vocabularies. They are copied here, plain tuples and
numbers, and tests/cli/test_choices.py checks each against the library's own, so a copy that
drifts fails the suite.
"""

# sgp-fit (diegocal.sgp.model, diegocal.sgp.regressor)
SGP_KINDS = ("sgp", "pr", "gp", "prgp")
SGP_INFERENCE = ("auto", "exact", "sparse")
SGP_INPUT_STREAMS = ("q", "qd", "qdd")
FRICTION_KINDS = ("viscous", "coulomb")
#: SGPOptions' defaults the options show
SGP_EXACT_MAX = 3000
SGP_N_INDUCING = 2000
SGP_RESTARTS = 2
SGP_MIN_NOISE = 1e-4

# stac and predict (diegocal.stac.robust, diegocal.stac.stac, diegocal.stac.predict)
STAC_METHODS = ("stac", "classical", "ekf", "nominal")
STAC_LOSSES = ("linear", "huber", "tukey")
STAC_SCHEDULES = ("lm-iter", "lm-batch", "bfgs")
SENSOR_TYPES = ("markers", "pots", "rotary", "linear", "tendon", "encoder")

# simulate (diegocal.sim.*)
PNEUMATIC_EXPERIMENTS = ("dynamic", "steady-state")
TRAJECTORIES = ("excitation", "whirl", "figure8-horizontal", "figure8-vertical", "pole-down", "pole-up")
#: effect -> domain (diegocal.sim.effects.VOCABULARY)
EFFECTS = {
    "link_offset": "kinematics",
    "sensor_nonlinearity": "kinematics",
    "backlash": "kinematics",
    "time_offset": "kinematics",
    "marker_slip": "kinematics",
    "marker_outliers": "kinematics",
    "swapped_labels": "kinematics",
    "coulomb_friction": "dynamics",
    "viscous_friction": "dynamics",
    "position_friction": "dynamics",
    "payload": "dynamics",
    "spring": "dynamics",
    "torque_offset": "dynamics",
    "armature": "dynamics",
    "coupled_friction": "dynamics",
    "torque_lag": "dynamics",
    "valve_delay": "pneumatics",
    "chamber_leak": "pneumatics",
    "supply_droop": "pneumatics",
    "pressure_offset": "pneumatics",
}
#: what SIZE means for a kinematic effect (diegocal.sim.kinematics.SIZE_UNITS)
KINEMATIC_SIZE_UNITS = {
    "link_offset": "in m, the distance the joint's origin moves (random direction), so every marker it carries",
    "sensor_nonlinearity": "in V, the transfer curve's departure from linear at the ends of the pot's range",
    "backlash": "in V, the dead band's full width on the reading (which lags by up to half of it)",
    "time_offset": "in s, the mocap clock's shift (sign random; need not be whole samples)",
    "marker_slip": "in m, the distance the marker moves on its link",
    "marker_outliers": "in m, the distance of every faulty reading from its marker",
    "swapped_labels": "in m, the partner's mean distance (the marker nearest SIZE is the partner)",
}

# diagnose and batch (diegocal.diagnose, diegocal.batch)
DOMAINS = ("kinematics", "dynamics", "pneumatics")
BATCH_COMMANDS = ("stac", "sgp-fit", "pneumatic-fit", "diagnose", "predict")
LOG_SUFFIXES = (".h5", ".hdf5", ".csv")
