"""The sensor causes' standard errors: marginal over the model's columns and each other, and
infinite along a direction the data do not fix (gains on every joint against identified inertias:
a common scale is the inertias')."""

from __future__ import annotations

import numpy as np

from diegocal.diagnose.dynamics_filters import marginal_covariance, marginal_variances


def test_the_variances_are_the_inverse_normal_matrix_and_infinite_where_degenerate():
    rng = np.random.default_rng(0)
    x = rng.standard_normal((200, 3))
    d = rng.standard_normal((200, 2))
    Z = np.hstack([x, d])
    gram = Z.T @ Z
    np.testing.assert_allclose(marginal_variances(gram, 3), np.diag(np.linalg.inv(gram))[3:], rtol=1e-9)
    d[:, 1] = x @ [1.0, -2.0, 0.5] - d[:, 0]  # the two together are in the model's span
    Z = np.hstack([x, d])
    assert np.isinf(marginal_variances(Z.T @ Z, 3)).all()


def test_the_covariance_is_the_inverse_where_fixed_and_never_indefinite():
    """A shape's derivative that is a model column to rounding (a velocity scale at its bound) has a
    Schur complement of either sign: its covariance is then zero, never negative (a negative
    widening of the amplitude's ± had made it NaN), and its variance infinite."""
    rng = np.random.default_rng(1)
    x = rng.standard_normal((300, 3)) * [1.0, 1e3, 1e-2]
    d = rng.standard_normal((300, 1))
    gram = np.hstack([x, d]).T @ np.hstack([x, d])
    cov, var = marginal_covariance(gram, 3)
    np.testing.assert_allclose(cov, np.linalg.inv(gram)[3:, 3:], rtol=1e-9)
    np.testing.assert_allclose(var, marginal_variances(gram, 3))
    signs = set()
    for k in range(40):
        d = x[:, 1:2] * (1.0 + 1e-15 * k) + 1e-12 * rng.standard_normal((300, 1))
        gram = np.hstack([x, d]).T @ np.hstack([x, d])
        S = gram[3:, 3:] - gram[3:, :3] @ np.linalg.pinv(gram[:3, :3]) @ gram[:3, 3:]
        signs.add(bool(S[0, 0] > 0))
        cov, var = marginal_covariance(gram, 3)
        assert np.linalg.eigvalsh(cov).min() >= 0.0
        assert np.isinf(var).all() or (var > 0).all()
    assert signs == {True, False}  # the complement came out of either sign over these draws
