"""A hidden Stribeck or load friction is named on its joint with its values (issue #31, item 5): the
simulator's shapes (a peak above Coulomb decaying over a velocity scale; a gear's friction growing
with the true links' torque), found with the defaults a user gets, their values within 3 standard
errors and a few per cent of the simulator's."""

from __future__ import annotations

import numpy as np
import pytest

from diegocal.diagnose import DiagnoseOptions, diagnose
from diegocal.robot import load_robot
from diegocal.robot.model import BUNDLED_ROBOTS
from diegocal.sim.dynamics import DynamicsOptions, simulate_dynamics


@pytest.fixture(scope="module")
def arm3():
    return load_robot(BUNDLED_ROBOTS / "arm3")


def _top(robot, effect, seed):
    opts = DynamicsOptions(duration=20.0, effects=(effect,), noise=0.01)
    log = simulate_dynamics(robot, opts, np.random.default_rng(seed))
    d = diagnose(log, robot, DiagnoseOptions(domain="dynamics"))
    assert d.findings, "nothing found"
    top = d.findings[0]
    cause, _, joint = effect.partition("=")[0].partition(":")
    assert (top.kind, top.cause, top.channel) == ("term", cause, joint), [f.term.label for f in d.findings]
    assert top.gain()["rmse_after"] < top.gain()["rmse_before"]
    return top, log.truth.effects[0]["values"]


def _assert_near(top, truth: dict, rel: float):
    for name, want in truth.items():
        p = next(p for p in top.term.parameters if p.name == name)
        assert abs(p.value - want) < min(3.0 * p.stderr, rel * want), (name, p.value, p.stderr, want)


@pytest.mark.parametrize("joint,amplitude,seed", [("joint2", 0.1, 3), ("joint3", 0.08, 5)])
def test_a_stribeck_friction_is_named_with_its_amplitude_and_velocity_scale(arm3, joint, amplitude, seed):
    """8-10 × the noise at zero velocity, decaying over 0.05 rad/s: the amplitude and the searched
    velocity scale within 3 SE and 10 %."""
    top, truth = _top(arm3, f"stribeck_friction:{joint}={amplitude}", seed)
    assert truth == {"amplitude": amplitude, "velocity_scale": 0.05}
    _assert_near(top, truth, 0.1)


@pytest.mark.parametrize("joint,coefficient,seed", [("joint2", 0.02, 3), ("joint3", 0.05, 5)])
def test_a_load_friction_is_named_with_its_coefficient(arm3, joint, coefficient, seed):
    """2-5 % of the joint's rigid-body torque (about 3-9 × the noise RMS): the coefficient within
    3 SE and 5 % (the term's column is the URDF's rigid body, the simulator's the true one: here the
    same)."""
    top, truth = _top(arm3, f"load_friction:{joint}={coefficient}", seed)
    assert truth == {"coefficient": coefficient}
    _assert_near(top, truth, 0.05)
