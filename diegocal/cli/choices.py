"""The words and defaults the options name, without importing the library that owns them.

`--help` must not import numpy, scipy or the fitting code (STYLE.md), yet the option help and
the parse-time checks need the library's vocabularies. Those of model-error causes come from
the light `diegocal.causes`, which the library reads too; the others are copied here, plain
tuples and numbers, and tests/cli/test_choices.py checks each against the library's own, so a
copy that drifts fails the suite.
"""

#: effect -> domain (EFFECTS), diagnose's DOMAINS, what SIZE means for a kinematic effect
#: (KINEMATIC_SIZE_UNITS): the cause registry's own, read when a command that names them is built
#: (the registry takes a fiftieth of a second to import, which no other help needs)
_FROM_CAUSES = {"EFFECTS": "VOCABULARY", "DOMAINS": "DOMAINS", "KINEMATIC_SIZE_UNITS": "KINEMATIC_SIZE_UNITS"}


def __getattr__(name: str):
    if name in _FROM_CAUSES:
        import diegocal.causes

        return getattr(diegocal.causes, _FROM_CAUSES[name])
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


# sgp-fit (diegocal.sgp.model, diegocal.sgp.regressor)
SGP_KINDS = ("sgp", "pr", "gp", "prgp")
SGP_INFERENCE = ("auto", "exact", "sparse")
SGP_INPUT_STREAMS = ("q", "qd", "qdd")
FRICTION_KINDS = ("viscous", "coulomb")
#: SGPOptions' defaults the options show
SGP_EXACT_MAX = 3000
SGP_N_INDUCING = 1000
SGP_RESTARTS = 2
SGP_MIN_NOISE = 1e-4

# stac and predict (diegocal.stac.robust, diegocal.stac.stac, diegocal.stac.predict)
STAC_METHODS = ("stac", "classical", "ekf", "nominal")
STAC_LOSSES = ("linear", "huber", "tukey")
STAC_SCHEDULES = ("lm-iter", "lm-batch", "bfgs")
#: StacOptions' safety cap on the alternations (diegocal.stac.result.MAX_ITERATIONS)
STAC_MAX_ITERATIONS = 500
SENSOR_TYPES = ("markers", "pots", "rotary", "linear", "tendon", "encoder")
SOURCE_TYPES = (*SENSOR_TYPES, "others")

# simulate (diegocal.sim.*)
PNEUMATIC_EXPERIMENTS = ("dynamic", "steady-state")
TRAJECTORIES = ("excitation", "whirl", "figure8-horizontal", "figure8-vertical", "pole-down", "pole-up")

# diagnose and batch (diegocal.diagnose, diegocal.batch)
BATCH_COMMANDS = ("stac", "sgp-fit", "pneumatic-fit", "diagnose", "predict")
LOG_SUFFIXES = (".h5", ".hdf5", ".csv")
