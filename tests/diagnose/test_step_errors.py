"""A found kinematic term's standard errors (:func:`diegocal.diagnose.kinematics_lin.step_errors`):
a parameter the data do not fix is not reported as known to a picometre."""

import numpy as np

from diegocal.diagnose.kinematics_lin import step_errors


def test_a_parameter_in_a_direction_the_data_do_not_fix_has_an_infinite_standard_error():
    """Three coefficients whose columns are x, 0 and 0 (a link offset whose dy and dz the markers'
    own positions absorb): dx gets its finite error, dy and dz an infinite one (the pseudo-inverse
    alone had given them 0)."""
    rng = np.random.default_rng(0)
    T = 400
    x = rng.normal(size=T)
    A = np.stack([x, 0 * x, 0 * x], axis=1)  # one row per frame
    e = rng.normal(size=T)  # standardised residuals (W the inverse variance)
    bread = A.T @ A
    scores = A * e[:, None]
    se = step_errors(bread, scores)
    assert np.isfinite(se[0]) and 0.5 / np.sqrt(T) < se[0] < 3 / np.sqrt(T)
    assert np.all(np.isinf(se[1:]))
    both = np.stack([x, rng.normal(size=T), 0 * x], axis=1)  # a second fixed direction stays finite
    se = step_errors(both.T @ both, both * e[:, None])
    assert np.all(np.isfinite(se[:2])) and np.isinf(se[2])
