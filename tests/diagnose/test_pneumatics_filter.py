"""The filtered-sensor rival of a chamber's named term (diegocal/diagnose/pneumatics_filter.py): the
filter's reading answers a ramp exactly, and a pressure sensor lagging through a first-order filter
(a shape no cause names, put on a clean session of the project's simulator by this test) is left
``unexplained`` with the rival's time constant, where a supply sag or a valve delay stood in for it
on the independent generator. A true sag stays named with the rival asked (tests/diagnose/
test_pneumatics.py)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from diegocal.diagnose import DiagnoseOptions, diagnose
from diegocal.diagnose.pneumatics_filter import through_filter
from diegocal.robot import load_robot
from diegocal.sim.effects import parse_effects
from diegocal.sim.pneumatics import PneumaticSimOptions, simulate_pneumatics
from tests.pneumatic.conftest import write_robot


def test_the_filter_s_reading_answers_a_ramp_exactly_from_each_reset():
    time = np.arange(0.0, 2.0, 0.01)
    k, tau = 30.0, 0.05
    p = 100.0 + k * time
    y = p - 4.0  # the reading 4 below the pressure at each reset
    out = through_filter(p, y, np.array([0, 100]), time, tau)
    for a, b in ((0, 100), (100, 200)):
        s = time[a:b] - time[a]
        exact = p[a:b] - k * tau + (y[a] - p[a] + k * tau) * np.exp(-s / tau)
        np.testing.assert_allclose(out[a:b], exact, atol=1e-9)


def slowed(log, chamber: str, tau: float):
    """``log`` with ``chamber``'s pressure read through a first-order filter of time constant ``tau``
    (the noise-free pressure filtered, the log's own noise and offset kept)."""
    from experiments.pneumatic_oov import slow_reading

    i = log.streams["pressure"].names.index(chamber)
    true = log.truth.signals["pressure"].data[:, i]
    new = slow_reading(true, log.time, tau)
    p = log.streams["pressure"].data.copy()
    p[:, i] += new - true
    return replace(log, streams={**log.streams, "pressure": replace(log.streams["pressure"], data=p)})


@pytest.fixture(scope="module")
def clean(tmp_path_factory):
    """A clean 60-s session of the project's simulator on tests/pneumatic's robot, and the robot."""
    robot = load_robot(write_robot(tmp_path_factory.mktemp("filter_robot")))
    options = PneumaticSimOptions(duration=60.0, substeps=5, seed=7, effects=parse_effects(()))
    return simulate_pneumatics(robot, options), robot


def elbow_flex(log, robot):
    return diagnose(log.without_truth(), robot, DiagnoseOptions(domain="pneumatics", chambers=("elbow.flex",)))


def test_a_slow_pressure_sensor_is_unexplained_with_its_time_constant(clean):
    log, robot = clean
    assert elbow_flex(log, robot).findings == ()  # the session itself has nothing to find
    result = elbow_flex(slowed(log, "elbow.flex", 0.045), robot)
    found = [(f.cause, f.channel) for f in result.findings]
    assert found == [("unexplained", "elbow.flex")], found
    (f,) = result.findings
    rival = f.evidence["rival"]
    assert rival["tau_s"] in (0.03, 0.045, 0.065)  # the grid's steps around 45 ms
    assert rival["open_loop_validation_gain"] > rival["term_open_loop_validation_gain"] + 0.2
    assert f.evidence["stand_in"]["term"].split(":")[0] in ("supply_droop", "valve_delay", "chamber_leak")
    (runner,) = f.runners_up  # the term that stood in, with what beat it on the open-loop error
    assert runner["why_not"].startswith("stood in: the pressure read through a first-order filter")
