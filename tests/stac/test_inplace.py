"""Two routes agree: the q-step written over its State (:mod:`diegocal.stac.inplace`) takes the same
step as :func:`~diegocal.stac.qphase.q_step`, to the bit, frames accepted and rejected alike, in one
thread or two; and :func:`relinearise` puts back the State at q."""

import numpy as np
import pytest
import synth

from diegocal.stac.inplace import q_step_in_place, relinearise
from diegocal.stac.qphase import q_step

FIELDS = ("s", "Rl", "pl", "xi", "ds_lin")


@pytest.mark.parametrize("jobs", [1, 2])
def test_in_place_step_equals_q_step(tree_robot, jobs):
    log, obs, params, noise, q0, lam = synth.q_step_start(tree_robot, 1100)  # three units of 504 frames
    # batch 7 and KINEMATICS_BATCH 500: units of 72 whole slices, the last ones shorter
    st = obs.state(q0, 500, keep=True)
    a = q_step(obs, params, noise, q0, lam, 7, jobs, True, obs.state(q0, 500, keep=True))
    b = q_step_in_place(obs, params, noise, q0, lam, st, 7, jobs, True)
    assert b[2] is st  # written over
    assert 0 < np.sum(a[1] > lam) < obs.n_frames  # some frames rejected their step, some accepted
    for x, y in zip((a[0], a[1], a[3]), (b[0], b[1], b[3]), strict=True):
        np.testing.assert_array_equal(y, x)
    assert a[4] == b[4]
    for name in FIELDS:
        np.testing.assert_array_equal(getattr(b[2], name), getattr(a[2], name))
    back = relinearise(obs, q0, st, 7, jobs)  # the State at q0 again, over the same arrays
    fresh = obs.state(q0, 500, keep=True)
    assert back is st
    for name in FIELDS:
        np.testing.assert_array_equal(getattr(back, name), getattr(fresh, name))
