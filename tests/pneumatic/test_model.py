"""The 9-parameter model, eq. (4.6)-(4.11), its exact step (4.7) and the parameter schema."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from diegocal.errors import InputFileError
from diegocal.pneumatic.model import step_vector, terms
from diegocal.pneumatic.params import NAMES, SPECS, ChamberParams

X = np.array([4.9, 1.5, 0.3, -20.0, 0.5, 0.3, 30.0, 0.1, 0.1])
CONSTS = (360.0, 260.0, 0.1)


def _samples(rng, n=50):
    return (
        rng.uniform(100, 620, n),
        rng.uniform(3, 7, n),
        rng.uniform(-1, 1, n),
        rng.normal(0, 2, n),
        np.full(n, 0.01),
    )


def test_analytic_jacobian_matches_finite_differences(rng):
    p, u, v, vd, h = _samples(rng)
    for x in (X, X * rng.uniform(0.5, 1.5, 9)):
        _, J = step_vector(x, p, u, v, vd, h, *CONSTS)
        for i in range(9):
            e = 1e-6 * max(1.0, abs(x[i]))
            xp, xm = x.copy(), x.copy()
            xp[i] += e
            xm[i] -= e
            fd = (
                step_vector(xp, p, u, v, vd, h, *CONSTS, jacobian=False)[0]
                - step_vector(xm, p, u, v, vd, h, *CONSTS, jacobian=False)[0]
            ) / (2 * e)
            np.testing.assert_allclose(J[:, i], fd, rtol=1e-5, atol=1e-7, err_msg=NAMES[i])


def test_exact_step_solves_the_ode_for_fixed_inputs():
    # eq. (4.7) is the exact solution of (4.6) while s and r are constant
    u, v, vd, p0, h = 5.7, 0.2, 1.0, 150.0, 0.05
    t = terms(X, u, v, vd, *CONSTS, jacobian=False)
    sol = solve_ivp(lambda _, p: (t.s - p) * t.r, (0, h), [p0], rtol=1e-12, atol=1e-10)
    assert step_vector(X, p0, u, v, vd, h, *CONSTS, jacobian=False)[0] == pytest.approx(
        sol.y[0, -1], rel=1e-8
    )


def test_step_is_stable_for_any_step_length():
    p = step_vector(X, 100.0, 6.5, 0.0, 0.0, 1e6, *CONSTS, jacobian=False)[0]
    s = terms(X, 6.5, 0.0, 0.0, *CONSTS, jacobian=False).s
    assert p == pytest.approx(s)


def test_steady_state_is_a_monotone_sigmoid_between_room_and_supply():
    u = np.linspace(3, 7, 41)
    s = terms(X, u, 0.0, 0.0, *CONSTS, jacobian=False).s  # eq. (4.10c) at vdot = 0
    assert (np.diff(s) > 0).all() and s.min() > 100 and s.max() < 620
    assert terms(X, X[0], 0.0, 0.0, *CONSTS, jacobian=False).s == pytest.approx(
        360.0
    )  # c1 = centre


def test_params_round_trip_and_bounds():
    c = ChamberParams.nominal(620.0, 100.0).from_vector(X, stderr=np.full(9, 0.1))
    assert (c.c_b, c.c_s, c.c_gamma) == (360.0, 260.0, 0.1)  # §4.4
    back = ChamberParams.from_dict(c.to_dict())
    np.testing.assert_array_equal(back.vector(), X)
    assert back.stderr["c5"] == 0.1
    bounds = {s.name: (s.lower, s.upper) for s in SPECS}
    assert bounds["c1"] == (2.0, 8.0) and bounds["c3"][0] == -1.0 and bounds["c8"] == (-1.0, 1.0)
    d = c.to_dict("c")
    with pytest.raises(InputFileError, match="lacks c7"):  # the valve's rate term left out
        ChamberParams.from_dict({**d, "baseline": [t for t in d["baseline"] if t["cause"] != "valve_rate"]})
    with pytest.raises(InputFileError, match="missing c7"):  # a layout 1 entry without c7
        ChamberParams.from_dict({**{n: 1.0 for n in NAMES if n != "c7"}, "c_b": 360.0, "c_s": 260.0})
