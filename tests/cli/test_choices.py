"""diegocal.cli.choices copies the library's vocabularies and defaults so that `--help` needs no
library import: each copy must equal the library's own."""

import dataclasses

from diegocal.batch import COMMANDS
from diegocal.cli import choices
from diegocal.diagnose import DOMAINS
from diegocal.report.logs import LOG_SUFFIXES
from diegocal.sgp.model import INFERENCE, INPUT_STREAMS, KINDS, SGPOptions
from diegocal.sgp.regressor import FRICTION_KINDS
from diegocal.sim.dynamics import TRAJECTORIES
from diegocal.sim.effects import VOCABULARY
from diegocal.sim.kinematics import SIZE_UNITS
from diegocal.sim.pneumatics import EXPERIMENTS
from diegocal.stac.predict import SENSOR_TYPES, SOURCE_TYPES
from diegocal.stac.result import MAX_ITERATIONS, StacOptions
from diegocal.stac.robust import LOSSES
from diegocal.stac.stac import SCHEDULES


def test_the_copies_equal_the_library():
    defaults = {f.name: f.default for f in dataclasses.fields(SGPOptions)}
    assert choices.SGP_KINDS == KINDS
    assert choices.SGP_INFERENCE == INFERENCE
    assert choices.SGP_INPUT_STREAMS == INPUT_STREAMS
    assert choices.FRICTION_KINDS == FRICTION_KINDS
    assert (choices.SGP_EXACT_MAX, choices.SGP_N_INDUCING, choices.SGP_RESTARTS, choices.SGP_MIN_NOISE) == (
        defaults["exact_max"],
        defaults["n_inducing"],
        defaults["restarts"],
        defaults["min_noise"],
    )
    assert choices.STAC_LOSSES == LOSSES
    assert choices.STAC_SCHEDULES == SCHEDULES
    assert choices.STAC_MAX_ITERATIONS == MAX_ITERATIONS == StacOptions().max_iterations
    assert choices.SENSOR_TYPES == SENSOR_TYPES and choices.SOURCE_TYPES == SOURCE_TYPES
    assert choices.PNEUMATIC_EXPERIMENTS == EXPERIMENTS
    assert choices.TRAJECTORIES == TRAJECTORIES
    assert choices.EFFECTS == VOCABULARY
    assert choices.KINEMATIC_SIZE_UNITS == SIZE_UNITS
    assert choices.DOMAINS == DOMAINS
    assert choices.BATCH_COMMANDS == tuple(COMMANDS)
    assert choices.LOG_SUFFIXES == LOG_SUFFIXES

