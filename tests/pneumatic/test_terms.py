"""The chamber model's terms: baseline c1..c9 by name, the extra terms, their Jacobians and fits."""

from dataclasses import replace

import numpy as np
import pytest

from diegocal.causes import causes_of
from diegocal.errors import InputFileError
from diegocal.pneumatic import FitOptions, chamber_data, fit_chamber
from diegocal.pneumatic.fit import volume_normalisation
from diegocal.pneumatic.model import BASELINE, ChamberModel, steady_state, step_vector
from diegocal.pneumatic.params import NAMES, ChamberParams
from diegocal.pneumatic.predict import next_step, predict_with_resets
from diegocal.pneumatic.synthetic import simulate_model
from diegocal.pneumatic.terms import CAUSES, PARTS, baseline_terms
from diegocal.terms import make_term, term_from_dict

X = np.array([4.9, 1.5, 0.3, -20.0, 0.5, 0.3, 30.0, 0.1, 0.1])
CONSTS = (360.0, 260.0, 0.1)
EXTRA = {"valve_delay": {"delay_s": 0.023}, "chamber_leak": {"leak": 0.4}, "supply_droop": {"droop": 2e-3},
         "pressure_offset": {"offset": 3.0}, "flow_saturation": {"sat": 0.7}}
SATURATED = ("flow_saturation", "chamber_leak", "supply_droop", "pressure_offset")


def _extra(causes=CAUSES, chamber="c"):
    return tuple(make_term(c, chamber, EXTRA[c]) for c in causes)


def _samples(rng, n=60, lags=12):
    u_lags = rng.uniform(3, 7, (n, lags + 1))
    return (rng.uniform(100, 620, n), u_lags[:, 0], rng.uniform(-1, 1, n), rng.normal(0, 2, n),
            np.full(n, 0.01), u_lags)


def test_baseline_terms_name_c1_to_c9_in_table_order():
    names = [p.name for t in baseline_terms() for p in t.parameters]
    assert sorted(names) == list(NAMES) and BASELINE.names == NAMES
    causes = [t.cause for t in baseline_terms()]
    assert causes == ["valve_steady_state", "volume_rate_steady", "valve_rate", "volume_rate_rate", "chamber_volume"]


def _check_jacobian(model, x, J, p, u, v, vd, h, lags):
    """Each column of ``J`` against central differences of the step's prediction."""
    for i, name in enumerate(model.names):
        e = 1e-6 * max(1.0, abs(x[i]))
        xp, xm = x.copy(), x.copy()
        xp[i] += e
        xm[i] -= e
        fd = (model.step(xp, p, u, v, vd, h, *CONSTS, lags, False)[0]
              - model.step(xm, p, u, v, vd, h, *CONSTS, lags, False)[0]) / (2 * e)
        np.testing.assert_allclose(J[:, i], fd, rtol=1e-5, atol=1e-6, err_msg=name)


@pytest.mark.parametrize("causes", [(), *[(c,) for c in CAUSES], CAUSES, ("flow_saturation",), SATURATED])
def test_jacobian_of_every_term_matches_finite_differences(rng, causes):
    model = ChamberModel(_extra(causes))
    p, u, v, vd, h, lags = _samples(rng)
    x = np.concatenate([X, [EXTRA[c][n] for c in causes for n in EXTRA[c]]])
    _, J = model.step(x, p, u, v, vd, h, *CONSTS, lags)
    assert J.shape == (p.size, model.n_params)
    _check_jacobian(model, x, J, p, u, v, vd, h, lags)


def test_extra_terms_at_zero_are_the_baseline(rng):
    p, u, v, vd, h, lags = _samples(rng)
    model = ChamberModel(tuple(make_term(c, "c") for c in CAUSES))
    x = np.concatenate([X, np.zeros(4)])
    a = model.step(x, p, u, v, vd, h, *CONSTS, lags, False)[0]
    b = step_vector(X, p, u, v, vd, h, *CONSTS, jacobian=False)[0]
    np.testing.assert_allclose(a, b, rtol=1e-12)


def test_each_term_moves_the_prediction_the_way_its_physics_says(rng):
    p, u, v, vd, h, lags = _samples(rng)
    base = step_vector(X, p, u, v, vd, h, *CONSTS, jacobian=False)[0]

    def with_(cause):
        model = ChamberModel(_extra((cause,)))
        return model.step(np.concatenate([X, list(EXTRA[cause].values())]), p, u, v, vd, h, *CONSTS, lags, False)[0]

    # a leak pulls toward the room pressure, a droop lowers what the supply can reach
    assert (with_("chamber_leak") <= base + 1e-9).all()
    assert (with_("supply_droop") <= base + 1e-9).all()
    # the valve delay answers an older command: the same as the baseline fed that command
    d = 0.02 / 0.01
    old = step_vector(X, p, lags[:, int(d)], v, vd, h, *CONSTS, jacobian=False)[0]
    model = ChamberModel(_extra(("valve_delay",)))
    np.testing.assert_allclose(model.step(np.append(X, 0.02), p, u, v, vd, h, *CONSTS, lags, False)[0], old)
    # an offset of the reading: predicting readings p + δ gives the baseline's prediction + δ
    model = ChamberModel(_extra(("pressure_offset",)))
    np.testing.assert_allclose(model.step(np.append(X, 3.0), p + 3.0, u, v, vd, h, *CONSTS, lags, False)[0],
                               base + 3.0)


def test_a_lasting_supply_sag_is_a_pressure_sensor_s_span_error(rng):
    # a sensor reading P_r + (1 + k)(p - P_r): the model's step on the true pressure, read by it, is
    # the step on the readings of the model with a lasting sag -k (P_c - P_r), c4 (1 + k) and the
    # ports' flow saturation sat / (1 + k) (the companion diagnose always fits)
    c_b, c_s, _ = CONSTS
    room, k, sat = c_b - c_s, -0.012, 0.7
    p, u, v, vd, h, lags = _samples(rng)
    plain = ChamberModel(_extra(("flow_saturation",)))
    truth = plain.step(np.append(X, sat), p, u, v, vd, h, *CONSTS, lags, False)[0]
    read = lambda x: room + (1.0 + k) * (x - room)  # noqa: E731
    model = ChamberModel(_extra(("flow_saturation", "supply_droop")))
    values = {**dict(zip(NAMES, X, strict=True)), "sat": sat / (1.0 + k), "droop": -k * 2.0 * c_s}
    values["c4"] *= 1.0 + k
    x = np.array([values[n] for n in model.names])
    sagged = model.step(x, read(p), u, v, vd, h, *CONSTS, lags, False)[0]
    np.testing.assert_allclose(sagged, read(truth), rtol=1e-12, atol=1e-9)


def test_params_with_terms_round_trip_through_yaml_mapping():
    c = ChamberParams.nominal(620.0, 100.0).from_vector(X).with_terms(_extra(chamber="elbow.ext"))
    assert c.full_vector().size == 13
    raw = c.to_dict()
    assert [t["cause"] for t in raw["terms"]] == list(CAUSES)
    back = ChamberParams.from_dict(raw)
    np.testing.assert_array_equal(back.full_vector(), c.full_vector())
    assert back.terms[1].channel == "elbow.ext" and back.terms[1].parameters[0].unit == "1/s"
    # a term read back from YAML is the chamber term of its cause: one Term type for every domain
    generic = term_from_dict(raw["terms"][2])
    assert ChamberModel((generic,)).names[-1] == "droop"
    # every pneumatic cause of the registry has its part of the model here
    assert set(PARTS) == set(causes_of("pneumatics"))
    with pytest.raises(InputFileError, match="unknown cause"):
        ChamberParams.from_dict({**raw, "terms": [{"cause": "valve_stiction", "channel": "x"}]})
    with pytest.raises(ValueError, match="one term per cause"):
        ChamberModel(_extra(("chamber_leak", "chamber_leak")))


def test_steady_state_with_offset_and_leak():
    c = ChamberParams.nominal(620.0, 100.0).from_vector(X)
    u = np.linspace(3, 7, 21)
    s = steady_state(c, u)
    off = c.with_terms(_extra(("pressure_offset",)))
    np.testing.assert_allclose(steady_state(off, u), s + 3.0)
    leak = c.with_terms(_extra(("chamber_leak",)))
    assert (steady_state(leak, u) < s).all() and (np.diff(steady_state(leak, u)) > 0).all()


def test_fit_recovers_extra_terms_on_data_made_by_the_model(robot, train_log):
    # Identifiability of the extra terms: the model with all four, noise 1 kPa -> within 4 SE.
    name = "shoulder.flex"
    v = train_log.streams["pots"].column("shoulder_pot")
    v_ref, v_scale = volume_normalisation(v)
    base = replace(ChamberParams.nominal(620.0, 100.0), v_ref=v_ref, v_scale=v_scale).from_vector(X)
    truth = base.with_terms(_extra(chamber=name))
    log = simulate_model(train_log, robot.sensors, {name: truth}, noise=1.0, seed=4)
    data = chamber_data(log.without_truth(), robot.sensors, name)
    start = tuple(make_term(c, name, {"delay_s": 0.02} if c == "valve_delay" else None) for c in CAUSES)  # a sample off
    fit = fit_chamber(data, FitOptions(drift_starts=0), terms=start)
    est = fit.params.full_vector()
    se_extra = [p.stderr for t in fit.params.terms for p in t.parameters]
    se = np.concatenate([[fit.params.stderr[n] for n in NAMES], se_extra])
    z = (est - truth.full_vector()) / se
    assert np.isfinite(se).all() and np.abs(z).max() < 4.0, np.round(z, 2)
    assert fit.rmse == pytest.approx(1.0, rel=0.05)
    # the fitted model predicts its own data: next step to the noise, open loop close to it
    assert np.std(next_step(fit.params, data) - data.p[1:]) == pytest.approx(1.0, rel=0.05)
    assert np.sqrt(np.mean((predict_with_resets(fit.params, data) - data.p) ** 2)) < 10.0


def test_fit_on_some_rows_uses_only_steps_inside_them(robot, train_log):
    data = chamber_data(train_log, robot.sensors, "elbow.flex")
    rows = np.zeros(data.n_samples, bool)
    rows[:1000] = rows[2000:3000] = True
    fit = fit_chamber(data, FitOptions(drift_starts=0), rows=rows)
    assert fit.n_samples == 999 + 999 and np.isnan(fit.drift_2s)


def test_flow_saturation_slows_the_rate_far_from_the_steady_state_and_its_pressure_derivative(rng):
    p, u, v, vd, h, lags = _samples(rng)
    sat = ChamberModel(_extra(("flow_saturation",)))
    x = np.concatenate([X, [0.7]])
    base = BASELINE.evaluate(X, p, u, v, vd, h, *CONSTS, jacobian=False)
    shaped = sat.evaluate(x, p, u, v, vd, h, *CONSTS, jacobian=False)
    np.testing.assert_allclose(shaped.s, base.s)
    assert (shaped.r <= base.r + 1e-12).all() and (shaped.r < base.r).any()
    # d p_next / d p (what the offset's column reads) against finite differences, with a leak
    model = ChamberModel(_extra(SATURATED))
    x = np.concatenate([X, [EXTRA[c][n] for c in SATURATED for n in EXTRA[c]]])
    at = model.index["offset"]
    _, J = model.step(x, p, u, v, vd, h, *CONSTS, lags)
    e = 1e-5
    fd = (model.step(x, p + e, u, v, vd, h, *CONSTS, lags, False)[0]
          - model.step(x, p - e, u, v, vd, h, *CONSTS, lags, False)[0]) / (2 * e)
    np.testing.assert_allclose(J[:, at], 1.0 - fd, rtol=1e-5, atol=1e-6)


SHAPED = (
    make_term("chamber_leak", "c", {"leak": 3.0}, extra={"shape": "orifice"}),
    make_term("supply_droop", "c", {"droop": 40.0}, extra={"shape": "flow"}),
    make_term("flow_saturation", "c", {"sat": 0.7}),
    make_term("pressure_offset", "c", {"offset": 3.0}),
)


ORIFICE_DROOP = make_term("supply_droop", "c", {"droop": 40.0}, extra={"shape": "orifice"})


@pytest.mark.parametrize(
    "terms", [SHAPED[:1], SHAPED[1:2], SHAPED[:2] + SHAPED[3:], SHAPED, (ORIFICE_DROOP,), (ORIFICE_DROOP, SHAPED[3])]
)
def test_jacobian_of_the_orifice_leak_and_the_flow_droop_matches_finite_differences(rng, terms):
    # their flows depend on the pressure at the step's start: the offset's column reads that too
    model = ChamberModel(terms)
    p, u, v, vd, h, lags = _samples(rng)
    x = np.concatenate([X, [t.values[0] for t in terms]])
    _, J = model.step(x, p, u, v, vd, h, *CONSTS, lags)
    _check_jacobian(model, x, J, p, u, v, vd, h, lags)


def test_an_orifice_leak_is_choked_above_twice_the_room_pressure_and_stops_at_it(rng):
    from diegocal.pneumatic.terms import orifice_outflow

    phi, dphi, _ = orifice_outflow(np.array([100.0, 150.0, 300.0, 600.0]), 100.0)
    assert phi[0] == 0.0 and phi[2:] == pytest.approx([300.0, 600.0]) and dphi[2:] == pytest.approx(1.0)
    assert 0.0 < phi[1] < 150.0
    p, u, v, vd, h, lags = _samples(rng)
    base = step_vector(X, p, u, v, vd, h, *CONSTS, jacobian=False)[0]
    leaky = ChamberModel(SHAPED[:1]).step(np.append(X, 3.0), p, u, v, vd, h, *CONSTS, lags, False)[0]
    assert (leaky <= base + 1e-9).all() and (leaky < base).any()


def test_a_flow_droop_sags_while_the_chamber_fills_and_not_once_it_is_full(rng):
    # a chamber at the supply pressure draws nothing: the flow-shaped sag is 0 there
    model = ChamberModel(SHAPED[1:2])
    x = np.append(X, 40.0)
    u = np.full(3, 7.0)
    p = np.array([150.0, 400.0, 620.0])
    t = model.evaluate(x, p, u, np.zeros(3), np.zeros(3), 0.01, *CONSTS, jacobian=False)
    b = BASELINE.evaluate(X, p, u, np.zeros(3), np.zeros(3), 0.01, *CONSTS, jacobian=False)
    sag = b.s - t.s
    assert sag[0] > sag[1] > 0.0 and sag[2] == pytest.approx(0.0, abs=1e-9)


def test_a_valve_delay_adds_to_the_sensor_lag(rng):
    p, u, v, vd, h, lags = _samples(rng)
    lag, delay = make_term("sensor_lag", "c", {"lag_s": 0.004}), make_term("valve_delay", "c", {"delay_s": 0.016})
    both = ChamberModel((lag, delay))
    one = ChamberModel(_extra(("valve_delay",)))
    a = both.step(np.concatenate([X, [0.004, 0.016]]), p, u, v, vd, h, *CONSTS, lags, False)[0]
    np.testing.assert_allclose(a, one.step(np.append(X, 0.02), p, u, v, vd, h, *CONSTS, lags, False)[0])


def test_an_orifice_droop_divides_the_drop_as_the_squares_of_the_areas(rng):
    # two restrictions in series: x = droop w for linear ones (flow), droop c_s w² for orifices, w
    # the port's conductance over the line's; at small sag orifice / flow = c_s w, the port's alone
    # (the same for any droop) and larger where the port is open wider; none at the supply pressure
    u = np.array([6.0, 7.0, 7.0])
    p = np.array([150.0, 150.0, 620.0])
    b = BASELINE.evaluate(X, p, u, np.zeros(3), np.zeros(3), 0.01, *CONSTS, jacobian=False)

    def sag(shape, droop):
        term = make_term("supply_droop", "c", {"droop": droop}, extra={"shape": shape})
        x = np.append(X, droop)
        return b.s - ChamberModel((term,)).evaluate(x, p, u, np.zeros(3), np.zeros(3), 0.01, *CONSTS,
                                                     jacobian=False).s

    w = [sag("orifice", d)[:2] / sag("flow", d)[:2] for d in (1e-4, 2e-4)]
    assert w[0] == pytest.approx(w[1], rel=1e-3) and 0.0 < w[0][0] < w[0][1]
    assert sag("orifice", 1e-4)[2] == pytest.approx(0.0, abs=1e-9)
