"""A found kinematic term is refined until it stops moving: Gauss-Newton steps on its parameters
alternate with STAC's refit of the calibration, which converges linearly; one step left a pot's
cubic coefficient several standard errors from the truth on diego logs."""

import math

import numpy as np
import pytest

from diegocal.diagnose import DiagnoseOptions, diagnose
from diegocal.diagnose.kinematics_refine import REFINE_TOL, moved
from diegocal.robot import load_robot, resolve_robot_dir
from diegocal.sim.effects import parse_effect
from diegocal.sim.kinematics import KinematicsOptions, simulate_kinematics
from diegocal.terms import make_term


def _curve(c2, c3, se=(0.002, 0.003)):
    return make_term("sensor_nonlinearity", "neck_a", [c2, c3], stderr=list(se))


def test_a_term_that_moved_by_more_than_the_tolerance_of_its_error_is_refined_again():
    before = (_curve(0.050, -0.0050),)
    step = 1.5 * REFINE_TOL * 0.003  # c3 moves by 1.5 x the tolerance of its standard error
    assert moved(before, (_curve(0.050, -0.0050 + step),), 0.5)
    assert not moved(before, (_curve(0.050, -0.0050 + step / 3.0),), 0.5)


def test_a_parameter_without_a_standard_error_does_not_keep_the_refinement_going():
    before = (_curve(0.050, -0.0050, se=(math.nan, math.nan)),)
    assert not moved(before, (_curve(0.060, 0.0050, se=(math.nan, math.nan)),), 0.5)


def test_a_clock_shift_moves_by_its_own_tolerance():
    shift = make_term("time_offset", "markers", [0.200], stderr=[1e-5])
    assert moved((shift,), (shift.with_values([0.210], [1e-5]),), 0.5)  # 5 % of itself
    assert not moved((shift,), (shift.with_values([0.2001], [1e-5]),), 0.5)  # 10 SE, 0.05 %


def test_a_term_new_to_the_model_is_not_a_move():
    offset = make_term("link_offset", "r_knee", [0.001, 0.0, 0.0], stderr=[1e-4] * 3)
    assert not moved((), (offset,), 0.5)
    shifted = offset.with_values(np.array([0.002, 0.0, 0.0]), np.full(3, 1e-4))
    assert moved((offset,), (shifted,), 0.5)


@pytest.mark.slow
def test_a_pots_curve_is_refined_to_the_truth_on_a_diego_log():
    """A 20-s diego log whose neck pot reads a parabola of its transmission: the term's cubic
    coefficient is 0 in truth. One refinement left it 3.6 of its standard errors from 0; refined
    until it stops moving, within 2."""
    robot = load_robot(resolve_robot_dir("diego", None))
    opts = KinematicsOptions(duration=20.0, effects=(parse_effect("sensor_nonlinearity"),))
    log = simulate_kinematics(robot, opts, np.random.default_rng(1))
    found = diagnose(log, robot, DiagnoseOptions(domain="kinematics")).findings
    truth = log.truth.effects[0]
    term = next(f.term for f in found if f.cause == "sensor_nonlinearity" and f.channel == truth["channel"])
    assert abs(term.value("c3")) <= 2.0 * term.stderrs[term.names.index("c3")]
