"""Two routes agree: the linearisation a q-step keeps in its State (the forward kinematics at the q
it ends at, frames accepted and rejected alike) equals a fresh one at that q, and the normal
equations formed from it equal those formed from the kinematics."""

import numpy as np
import synth

from diegocal.stac.qphase import normal_equations, q_step


def test_kept_linearisation_equals_a_fresh_one(tree_robot):
    log, obs, params, noise, q0, lam = synth.q_step_start(tree_robot, 6)
    q1, lam1, st1, _, _ = q_step(obs, params, noise, q0, lam, batch=7)
    assert 0 < np.sum(lam1 > lam) < obs.n_frames  # some frames rejected their step, some accepted
    fresh = obs.linearise(q1)
    kept = st1.linearisation(slice(None))
    for name in ("s", "Rl", "pl", "xi", "ds_lin"):
        np.testing.assert_allclose(getattr(kept, name), getattr(fresh, name), rtol=1e-12, atol=1e-12)
    sl = slice(3, 17)
    a = normal_equations(obs, params, noise, q1, sl, True)
    b = normal_equations(obs, params, noise, q1, sl, True, st1)
    for x, y in zip((a[0].dense(), *a[1:3]), (b[0].dense(), *b[1:3]), strict=True):
        np.testing.assert_allclose(y, x, rtol=1e-12, atol=1e-12)
    assert a[4].keys() == b[4].keys() and all(np.isclose(a[4][k], b[4][k], rtol=1e-12) for k in a[4])
    # a second step from the kept State takes the same step as one from the kinematics
    q2a = q_step(obs, params, noise, q1, lam1, batch=7)[0]
    q2b = q_step(obs, params, noise, q1, lam1, batch=7, st=st1)[0]
    np.testing.assert_allclose(q2b, q2a, rtol=1e-12, atol=1e-12)
