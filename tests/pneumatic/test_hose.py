"""The supply hose (``supply_droop`` of shape ``hose``): a line pressure state of its own, stepped by
the exact step (4.7); its limits (the flow shape's bare line, a lasting sag), its Jacobian through
the recursion, and a fit that recovers it on data the model made."""

from dataclasses import replace

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from diegocal.pneumatic import FitOptions, chamber_data, fit_chamber
from diegocal.pneumatic.fit import _Problem, volume_normalisation
from diegocal.pneumatic.model import BASELINE, ChamberModel, LineState
from diegocal.pneumatic.params import ChamberParams
from diegocal.pneumatic.predict import next_step, predict_with_resets
from diegocal.pneumatic.synthetic import simulate_model
from diegocal.terms import make_term

X = np.array([4.9, 1.5, 0.3, -20.0, 0.5, 0.3, 30.0, 0.1, 0.1])
CONSTS = (360.0, 260.0, 0.1)


def _hose(droop=40.0, tau=0.02, channel="c"):
    return make_term("supply_droop", channel, {"droop": droop}, extra={"shape": "hose", "tau_s": tau})


def _series(rng, n=80):
    """A series of consecutive steps: pressure, command (held for a few steps), volume, its rate."""
    u = np.repeat(rng.uniform(3.0, 7.0, n // 4 + 1), 4)[:n]
    return rng.uniform(100, 620, n), u, rng.uniform(-1, 1, n), rng.normal(0, 2, n), np.full(n, 0.01)


def test_the_hose_step_solves_its_ode_and_the_chamber_reads_the_step_s_mean():
    # tau dΔ/dt = x (P_c - p) - (1 + x) Δ with x and p held: eq. (4.7)'s form, solved exactly
    model = ChamberModel((_hose(),))
    x = np.append(X, 40.0)
    p, u, v, vd, h = np.array([150.0, 150.0]), np.array([6.5, 6.5]), np.zeros(2), np.zeros(2), np.full(2, 0.02)
    load = model._hose_load(x, p, u, v, vd, h, CONSTS, False)[0][0]
    gap, tau = CONSTS[0] + CONSTS[1] - 150.0, 0.02
    mean, end = model.line_step(x, 0.0, p[:1], u[:1], v[:1], vd[:1], h[:1], *CONSTS)
    sol = solve_ivp(lambda _, d: (load * gap - (1 + load) * d) / tau, (0, 0.02), [0.0], rtol=1e-12, atol=1e-12,
                    dense_output=True)
    assert end[0] == pytest.approx(sol.y[0, -1], rel=1e-8)
    grid = np.linspace(0.0, 0.02, 2001)
    assert mean[0] == pytest.approx(np.trapezoid(sol.sol(grid)[0], grid) / 0.02, rel=1e-6)
    # from rest the line starts at its equilibrium, the flow shape's sag
    line = model.line(x, p, u, v, vd, h, *CONSTS)
    assert line.start[0] == pytest.approx(gap * load / (1 + load)) and line.mean[1] == pytest.approx(line.start[0])


def test_a_small_hose_is_the_bare_line_and_a_large_one_a_sag_that_lasts(rng):
    p, u, v, vd, h = _series(rng)
    x = np.append(X, 40.0)
    flow = ChamberModel((make_term("supply_droop", "c", {"droop": 40.0}, extra={"shape": "flow"}),))
    bare = flow.step(x, p, u, v, vd, h, *CONSTS, jacobian=False)[0]
    # the flow shape's sag also reads p through the step (s_p); the hose holds it: compare the sags
    small = ChamberModel((_hose(tau=1e-12),))
    line = small.line(x, p, u, v, vd, h, *CONSTS)
    star = small._line_parts(x, p, u, v, vd, h, CONSTS, False)[0]
    np.testing.assert_allclose(line.mean, star, rtol=1e-6, atol=1e-6)
    assert np.abs(small.step(x, p, u, v, vd, h, *CONSTS, jacobian=False, line=line)[0] - bare).max() < 5.0
    large = ChamberModel((_hose(tau=1e6),))
    line = large.line(x, p, u, v, vd, h, *CONSTS)
    np.testing.assert_allclose(line.mean, line.start[0], rtol=1e-5)  # it never moves from its start


def test_a_model_with_a_hose_asks_for_its_line():
    with pytest.raises(ValueError, match="supply hose"):
        ChamberModel((_hose(),)).step(np.append(X, 40.0), 300.0, 5.0, 0.0, 0.0, 0.01, *CONSTS)


@pytest.mark.parametrize("others", [(), ("pressure_offset",), ("valve_delay", "pressure_offset", "chamber_leak")])
def test_the_jacobian_through_the_hose_s_recursion_matches_finite_differences(rng, others):
    extra = {"pressure_offset": {"offset": 3.0}, "valve_delay": {"delay_s": 0.023}, "chamber_leak": {"leak": 0.4}}
    terms = (_hose(), *(make_term(c, "c", extra[c]) for c in others))
    model = ChamberModel(terms)
    p, u, v, vd, h = _series(rng)
    lags = np.stack([np.roll(u, k) for k in range(model.n_lags(0.01) + 1)], axis=1) if model.has_delay else None
    x = np.concatenate([X, [t.values[0] for t in terms]])
    reset = np.zeros(p.size, bool)
    reset[40] = True  # a gap: the hose restarts at its equilibrium

    def pred(x, jacobian):
        line = model.line(x, p, u, v, vd, h, *CONSTS, reset, jacobian)
        return model.step(x, p, u, v, vd, h, *CONSTS, lags, jacobian, line)

    _, J = pred(x, True)
    for i, name in enumerate(model.names):
        e = 1e-6 * max(1.0, abs(x[i]))
        xp, xm = x.copy(), x.copy()
        xp[i] += e
        xm[i] -= e
        fd = (pred(xp, False)[0] - pred(xm, False)[0]) / (2 * e)
        np.testing.assert_allclose(J[:, i], fd, rtol=1e-5, atol=1e-6, err_msg=name)


def test_fit_recovers_a_hose_on_data_made_by_the_model(robot, train_log):
    name = "shoulder.flex"
    v = train_log.streams["pots"].column("shoulder_pot")
    v_ref, v_scale = volume_normalisation(v)
    base = replace(ChamberParams.nominal(620.0, 100.0), v_ref=v_ref, v_scale=v_scale).from_vector(X)
    truth = base.with_terms((_hose(60.0, 0.02, name),))
    log = simulate_model(train_log, robot.sensors, {name: truth}, noise=1.0, seed=5)
    data = chamber_data(log.without_truth(), robot.sensors, name)
    rows = np.ones(data.n_samples, bool)
    rows[3000:3200] = False  # a block edge: the fit's hose restarts after it
    problem = _Problem(data, base, ChamberModel((_hose(30.0, 0.02, name),)), rows)
    assert isinstance(problem._line(truth.full_vector(), False), LineState)
    fit = fit_chamber(data, FitOptions(drift_starts=0), terms=(_hose(30.0, 0.02, name),), rows=rows)
    droop = fit.params.terms[0].parameters[0]
    assert abs(droop.value - 60.0) < 4.0 * droop.stderr, (droop.value, droop.stderr)
    assert fit.rmse == pytest.approx(1.0, rel=0.05)
    assert np.std(next_step(fit.params, data) - data.p[1:]) == pytest.approx(1.0, rel=0.05)
    # open loop the hose is stepped with the predicted pressure: close to the noise, and better
    # than the baseline refitted without it
    plain = fit_chamber(data, FitOptions(drift_starts=0), rows=rows)
    err = [np.sqrt(np.mean((predict_with_resets(f.params, data) - data.p) ** 2)) for f in (fit, plain)]
    assert err[0] < 0.8 * err[1], err
    assert BASELINE.n_params == 9
