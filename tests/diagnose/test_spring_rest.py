"""A spring whose rest angle is neither the joint's zero nor its mean is one spring with its rest
angle fitted, not a spring beside a torque offset; a torque offset is not named a spring.

The torques are the arm3 simulator's with a spring (or an offset) added by hand on joint2, so that
its rest angle lies where no proposal puts it.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from diegocal.diagnose import DiagnoseOptions, diagnose
from diegocal.diagnose.dynamics import adapters
from diegocal.io.log import make_stream
from diegocal.robot import load_robot
from diegocal.robot.model import BUNDLED_ROBOTS
from diegocal.sim.dynamics import DynamicsOptions, simulate_dynamics
from diegocal.terms import make_term

NOISE = 0.01  # N·m, the simulator's default torque noise


@pytest.fixture(scope="module")
def arm3():
    return load_robot(BUNDLED_ROBOTS / "arm3")


def with_torque(robot, added, seed=3):
    """A clean arm3 log (20 s) with ``added(q)`` (T,) N·m on joint2's measured torque."""
    log = simulate_dynamics(robot, DynamicsOptions(duration=20.0, noise=NOISE), np.random.default_rng(seed))
    tau = log.stream("tau")
    data = tau.data.copy()
    data[:, 1] += added(log.stream("q").data[:, 1])
    return replace(log, streams={**log.streams, "tau": make_stream(tau.names, data)}), log.stream("q").data[:, 1]


def test_a_spring_at_rest_off_the_joints_zero_and_mean_is_one_spring(arm3):
    clean, q = with_torque(arm3, lambda q: 0.0)
    lo, hi = np.quantile(q, [0.0, 1.0])
    rest = float(lo + 0.8 * (hi - lo))
    stiffness = 8 * NOISE / float(np.sqrt(np.mean((q - rest) ** 2)))  # RMS torque 8 × the noise
    log, _ = with_torque(arm3, lambda x: stiffness * (x - rest))
    d = diagnose(log, arm3, DiagnoseOptions(domain="dynamics"))
    assert [(f.cause, f.channel) for f in d.findings] == [("spring", "joint2")]
    p = {x.name: x for x in d.findings[0].term.parameters}
    assert abs(p["stiffness"].value - stiffness) < 3 * p["stiffness"].stderr, p
    assert abs(p["rest_angle"].value - rest) < 3 * p["rest_angle"].stderr, (p, rest)


def test_a_torque_offset_is_not_named_a_spring(arm3):
    log, _ = with_torque(arm3, lambda q: np.full_like(q, 6 * NOISE))
    d = diagnose(log, arm3, DiagnoseOptions(domain="dynamics"))
    assert [(f.cause, f.channel) for f in d.findings] == [("torque_offset", "joint2")]
    offset = d.findings[0].term.parameters[0]
    assert abs(offset.value - 6 * NOISE) < 3 * offset.stderr


def test_the_simpler_of_an_offset_and_a_spring_that_fit_as_well_is_named(arm3):
    """An offset beside a slope of 1.5 × the noise RMS: a spring with its rest angle and a torque
    offset remove the same held-out error to within the noise; the offset, which has one parameter
    to the spring's two (stiffness and rest angle), is named, the spring said beside it."""
    _, q = with_torque(arm3, lambda q: 0.0, seed=4)
    slope = 1.5 * NOISE / float(np.sqrt(np.mean((q - q.mean()) ** 2)))
    log, _ = with_torque(arm3, lambda x: 6 * NOISE + slope * (x - q.mean()), seed=4)
    d = diagnose(log, arm3, DiagnoseOptions(domain="dynamics"))
    top = d.findings[0]
    assert (top.cause, top.channel) == ("torque_offset", "joint2")
    assert "spring:joint2" in top.evidence.get("indistinguishable_causes", [])


def test_a_rest_angle_an_offset_on_its_joint_leaves_undetermined_has_no_standard_error(arm3):
    """Beside a torque offset on its joint the rest angle only moves a constant the offset takes
    back: it is held, and its standard error is unknown (NaN), not the one it had alone."""
    log, _ = with_torque(arm3, lambda x: 0.5 * (x - 0.3))
    (adapter,) = adapters(log, arm3, None)
    train = np.arange(len(adapter.time)) < 0.6 * len(adapter.time)
    spring = make_term("spring", "joint2", {"rest_angle": 0.1}, stderr={"rest_angle": 0.01})
    alone = {t.cause: t for t in adapter.fit((spring,), train).terms}["spring"]
    assert np.isfinite(alone.parameters[1].stderr) and abs(alone.value("rest_angle") - 0.3) < 0.05
    both = {t.cause: t for t in adapter.fit((spring, make_term("torque_offset", "joint2")), train).terms}
    assert both["spring"].value("rest_angle") == 0.1 and np.isnan(both["spring"].parameters[1].stderr)


def test_a_runner_up_that_removed_more_but_has_more_parameters_says_so():
    """The one-SE rule's choice is said as such, not as 'explains more'."""
    from diegocal.diagnose.engine import _runner_up
    from diegocal.diagnose.stats import OutOfSample
    from diegocal.diagnose.types import Candidate, Tested

    def tested(term, sse_after):
        test = OutOfSample(1.0, 20.0, 10, 0.0, 100.0, sse_after, 5, np.zeros(3))
        return Tested(term, ("joint2",), test, 4.0, True, 1, Candidate(term, {}))

    spring = tested(make_term("spring", "joint2", {"rest_angle": 0.2}), 10.0)
    offset = tested(make_term("torque_offset", "joint2"), 10.4)
    assert "fewer parameters and fits as well" in _runner_up(spring, offset, {})["why_not"]
    assert "explains more" in _runner_up(offset, spring, {})["why_not"]
