"""The sensor causes' standard errors: marginal over the model's columns and each other, and
infinite along a direction the data do not fix (gains on every joint against identified inertias:
a common scale is the inertias')."""

from __future__ import annotations

import numpy as np

from diegocal.diagnose.dynamics_filters import marginal_variances


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
