"""STAC from a warm start (where a fit of nearly the same model ended) ends where the cold fit
does, in a few iterations: a diagnosis refits its extended model after each small step of a term."""

import numpy as np
import synth

from diegocal.stac.result import StacOptions, WarmStart
from diegocal.stac.stac import calibrate


def test_a_warm_start_ends_where_the_cold_fit_does_in_a_few_iterations(tree_robot):
    log = synth.simulate(tree_robot, 400, seed=3, occlusion=0.2)
    cold = calibrate(log, tree_robot)
    warm = calibrate(log, tree_robot, start=WarmStart(cold.calibration, cold.q))
    assert warm.calibration.fit.converged
    assert warm.calibration.fit.iterations <= 3 < cold.calibration.fit.iterations
    for name in ("gain", "bias", "marker_xyz"):
        a, b = getattr(cold.calibration, name), getattr(warm.calibration, name)
        se = getattr(cold.calibration, f"{name}_se")
        ok = np.isfinite(se)  # the sensors the fit estimates (the others keep their nominal values)
        assert ok.sum() > 3 and np.all(np.abs(a - b)[ok] <= 0.05 * se[ok]), name
        np.testing.assert_array_equal(a[~ok], b[~ok])


def test_a_warm_start_that_does_not_fit_the_fit_is_ignored(tree_robot):
    log = synth.simulate(tree_robot, 200, seed=4, occlusion=0.2)
    cold = calibrate(log, tree_robot)
    short = WarmStart(cold.calibration, cold.q[:-1])  # q of other frames: the nominal start instead
    again = calibrate(log, tree_robot, start=short)
    assert again.calibration.fit.iterations == cold.calibration.fit.iterations
    np.testing.assert_array_equal(again.calibration.gain, cold.calibration.gain)
    huber = calibrate(log, tree_robot, StacOptions(loss="huber"), start=WarmStart(cold.calibration, cold.q))
    assert huber.calibration.fit.iterations > 3
