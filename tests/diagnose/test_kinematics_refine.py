"""A found kinematic term is refined until it stops moving: Gauss-Newton steps on its parameters
alternate with STAC's refit of the calibration, which converges linearly; one step left a pot's
cubic coefficient several standard errors from the truth on diego logs."""

import math
from functools import partial

import numpy as np
import pytest

from diegocal.diagnose import DiagnoseOptions, diagnose, kinematics, kinematics_sweep
from diegocal.diagnose.kinematics import KinematicsAdapter
from diegocal.diagnose.kinematics_refine import REFINE_TOL, jumped, moved
from diegocal.diagnose.kinematics_sweep import Sweep
from diegocal.evaluate import split_blocks
from diegocal.robot import load_robot, resolve_robot_dir
from diegocal.sim.effects import parse_effect
from diegocal.sim.kinematics import KinematicsOptions, simulate_kinematics
from diegocal.terms import make_term


@pytest.fixture(scope="module")
def curved():
    """A 20-s finger log whose dip pot reads a curve of its transmission, the adapter and the
    training frames (ten contiguous blocks, the engine's split)."""
    robot = load_robot(resolve_robot_dir("finger", None))
    opts = KinematicsOptions(duration=20.0, effects=(parse_effect("sensor_nonlinearity:dip"),))
    log = simulate_kinematics(robot, opts, np.random.default_rng(3))
    return KinematicsAdapter(log, robot), split_blocks(log.n_samples, 10).mask("train")


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


def test_a_clock_shift_stops_within_its_own_tolerance_and_its_standard_error():
    """A shift's refinement goes on while it moves by 2 % of itself, or by 0.2 of its standard
    error: a 30-s iCub log's 0.060-s shift stopped after a step of 3.6 SE, 2.1 SE short."""
    shift = make_term("time_offset", "markers", [0.200], stderr=[1e-5])
    assert moved((shift,), (shift.with_values([0.210], [1e-5]),), 0.5)  # 5 % of itself
    assert moved((shift,), (shift.with_values([0.2001], [1e-5]),), 0.5)  # 10 SE, 0.05 %
    assert not moved((shift,), (shift.with_values([0.200001], [1e-5]),), 0.5)  # 0.1 SE
    loose = shift.with_values([0.200], [1.0])
    assert moved((loose,), (loose.with_values([0.210], [1.0]),), 0.5)  # 5 %, 0.01 SE


def test_a_clock_shift_that_moved_a_sample_or_more_jumped():
    """STAC is started where the fit before ended (warm) unless the step moved the markers' clock
    by a sample or more."""
    shift = make_term("time_offset", "markers", [0.045], stderr=[1e-4])
    assert jumped((shift,), (shift.with_values([0.057], [1e-4]),), 0.01)
    assert not jumped((shift,), (shift.with_values([0.0591], [1e-4]),), 0.02)
    assert not jumped((_curve(0.05, -0.005),), (_curve(0.5, -0.5),), 0.01)  # not a clock


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


def test_a_step_reads_the_training_blocks_only(curved, monkeypatch):
    """A Gauss-Newton step's sums are all over the training frames: sweeping only the blocks that
    hold them gives the same step and the same standard errors as sweeping every block."""
    adapter, train = curved
    monkeypatch.setattr(kinematics_sweep, "SWEEP_FRAMES", 37)  # blocks inside the held-out ones
    fitted = adapter.fit_once((adapter._own(make_term("sensor_nonlinearity", "dip", [0.0, 0.0]), train),), train)
    swept = []

    def sweep(fitted, adapter, train_only=False, every=False):
        s = Sweep(fitted, adapter, train_only=train_only and not every)
        swept.append(len(s.slices))
        return s

    monkeypatch.setattr(kinematics, "Sweep", sweep)
    got = adapter.refine_step(fitted)
    monkeypatch.setattr(kinematics, "Sweep", partial(sweep, every=True))
    want = adapter.refine_step(fitted)
    assert swept[0] < swept[1]  # the held-out blocks skipped
    np.testing.assert_allclose(got[0].values, want[0].values, rtol=1e-10)
    np.testing.assert_allclose(got[0].stderrs, want[0].stderrs, rtol=1e-10)
    assert np.all(got[0].values != 0.0)


def test_refinements_track_the_training_frames_and_the_last_one_every_frame(curved, monkeypatch):
    """Whether a step is the last is known from the step: the fits before it track q on the
    training frames only (all the next step reads), the last on every frame, where q ends where
    tracking the final model would leave it (not where the first fit left the held-out frames)."""
    adapter, train = curved
    sizes, made, real = [], [], kinematics.predict

    def predict(log, *args, **kwargs):
        sizes.append(log.n_samples)
        made.append(real(log, *args, **kwargs))
        return made[-1]

    monkeypatch.setattr(kinematics, "predict", predict)
    fitted = adapter.fit((make_term("sensor_nonlinearity", "dip", [0.0, 0.0]),), train)
    T = train.size
    assert len(sizes) >= 3  # the first fit, a refinement on the training frames at least, the last
    assert sizes[0] == sizes[-1] == T
    assert sizes[1:-1] == [int(train.sum())] * (len(sizes) - 2)
    both = ("pots", "markers")
    again = real(fitted.applied.log, fitted.applied.robot, fitted.cal, both, both, adapter.options, q_init=fitted.q)
    held = ~train
    assert np.abs(made[0].q[held] - fitted.q[held]).max() > 1e-3  # the refinements moved q there
    np.testing.assert_allclose(again.q[held], fitted.q[held], atol=1e-5)


def test_a_refinement_the_cap_ends_while_it_moves_says_so(curved, monkeypatch):
    """With the cap at one step (the first always moves the term from the candidate's linear
    estimate) the fit says in words that the cap ended it (diagnose writes converged: false); with
    the default cap it stops at the tolerance, here after its second step, and says nothing."""
    from diegocal.diagnose import kinematics_refine

    adapter, train = curved
    term = make_term("sensor_nonlinearity", "dip")
    assert adapter.fit((term,), train).unconverged == ()
    steps = []
    refine = KinematicsAdapter.refine_step
    monkeypatch.setattr(KinematicsAdapter, "refine_step", lambda self, f: steps.append(f.terms) or refine(self, f))
    monkeypatch.setattr(kinematics_refine, "REFINE_MAX", 1)
    fitted = adapter.fit((term,), train)
    assert len(steps) == 1 and moved(steps[0], fitted.terms, 0.5)  # the step moved it
    (why,) = fitted.unconverged
    assert "refinement stopped at its cap of 1 step(s)" in why and "sensor_nonlinearity:dip by" in why
