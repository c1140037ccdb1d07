"""Parametric part: regressor × parameters equals pinocchio.rnea (+ friction); base parameters."""

import numpy as np
import pinocchio as pin
import pytest

from diegocal.sgp import SGPOptions, base_parameters, fit_dynamics, full_regressor, true_parameters
from diegocal.sgp.regressor import CHUNK, base_regressor, parameter_names


def _states(robot, T, seed):
    rng = np.random.default_rng(seed)
    n = robot.n_joints
    return (
        rng.uniform(robot.lower, robot.upper, (T, n)),
        rng.standard_normal((T, n)),
        rng.standard_normal((T, n)),
    )


def test_regressor_times_parameters_equals_rnea_plus_friction(arm2):
    q, qd, qdd = _states(arm2, 20, 1)
    fric = {"viscous": np.array([0.3, 0.2]), "coulomb": np.array([0.15, 0.1])}
    F = full_regressor(arm2, q, qd, qdd, ("viscous", "coulomb"))
    w = true_parameters(arm2, fric)
    rnea = np.array([pin.rnea(arm2.model, arm2.data, q[i], qd[i], qdd[i]) for i in range(20)])
    expected = rnea + fric["viscous"] * qd + fric["coulomb"] * np.sign(qd)
    np.testing.assert_allclose(F @ w, expected, atol=1e-10)
    assert F.shape == (20, 2, 24) and len(parameter_names(arm2)) == 24


def test_rigid_body_only_regressor(arm2):
    q, qd, qdd = _states(arm2, 5, 2)
    F = full_regressor(arm2, q, qd, qdd, ())
    rnea = np.array([pin.rnea(arm2.model, arm2.data, q[i], qd[i], qdd[i]) for i in range(5)])
    np.testing.assert_allclose(F @ true_parameters(arm2, friction=()), rnea, atol=1e-10)


def test_base_parameters_preserve_torques(arm2):
    base = base_parameters(arm2, seed=3)
    q, qd, qdd = _states(arm2, 30, 4)
    F = full_regressor(arm2, q, qd, qdd)
    w = np.random.default_rng(5).standard_normal(F.shape[2])
    np.testing.assert_allclose(base.project(F) @ base.from_full(w), F @ w, atol=1e-9)
    # planar 2-link arm with gravity: 2×(m·c_x, m·c_z, I_yy)-type combinations → few base params
    assert 4 <= base.n_base < 24
    assert np.linalg.matrix_rank(base.project(F).reshape(-1, base.n_base)) == base.n_base


def test_base_regressor_in_chunks_equals_the_projected_full_one(arm2):
    """Built a chunk at a time (a long log's full regressor is never held), the same numbers."""
    base = base_parameters(arm2, seed=3)
    q, qd, qdd = _states(arm2, CHUNK + 7, 6)
    F = full_regressor(arm2, q, qd, qdd)
    np.testing.assert_array_equal(base_regressor(arm2, q, qd, qdd, base), base.project(F))
    np.testing.assert_array_equal(base_regressor(arm2, q, qd, qdd, base, rows=[1]), base.project(F[:, [1]]))


@pytest.mark.parametrize("noise", [0.0, 0.05])
def test_pr_recovers_true_base_parameters(arm2, simulate, friction, noise):
    log, _ = simulate(arm2, T=300, seed=7, noise=noise)
    model = fit_dynamics(log, arm2, SGPOptions(kind="pr"))
    est = model.parametric_
    truth = model.base_.from_full(true_parameters(arm2, friction))
    if noise == 0.0:
        np.testing.assert_allclose(est.values, truth, rtol=1e-4, atol=1e-5)
    else:
        z = (est.values - truth) / est.stderr
        assert np.all(np.abs(z) < 4.0), z  # within standard errors
        assert np.sqrt(np.mean(z**2)) < 2.0
        assert np.all(est.stderr > 0)
