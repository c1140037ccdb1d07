"""Dynamics terms (diegocal.sgp.terms): friction is two ordinary terms the regressor is built from,
extra terms add exact regressor columns that a DynamicsModel fits with W, the lag filter is a
first-order sensor, and a model with terms survives the sgp/ bundle (old bundles still load)."""

from __future__ import annotations

import numpy as np
import pytest

from diegocal.causes import MIN_SMOOTHING, causes_of
from diegocal.errors import InputFileError
from diegocal.robot import load_robot
from diegocal.robot.model import BUNDLED_ROBOTS
from diegocal.sgp import SGPOptions, load_model
from diegocal.sgp.backlash import CAUSE as BACKLASH
from diegocal.sgp.model import DynamicsModel
from diegocal.sgp.regressor import full_regressor
from diegocal.sgp.store import save_model
from diegocal.sgp.terms import COLUMNS, FILTERS, columns, friction_terms, lag_filter, term_columns
from diegocal.terms import Region, make_term, term_from_dict


@pytest.fixture(scope="module")
def arm3():
    return load_robot(BUNDLED_ROBOTS / "arm3")


def states(robot, T=400, seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(T) * 0.01
    w = rng.uniform(0.5, 2.0, robot.n_joints)
    q = 0.8 * np.sin(w * t[:, None]) + 0.3
    qd = 0.8 * w * np.cos(w * t[:, None])
    qdd = -0.8 * w**2 * np.sin(w * t[:, None])
    return t, q, qd, qdd


def test_friction_columns_of_the_regressor_are_the_friction_terms(arm3):
    _, q, qd, qdd = states(arm3)
    F = full_regressor(arm3, q, qd, qdd, ("viscous", "coulomb"))
    n = arm3.n_joints
    cols = term_columns(friction_terms(arm3.joint_names, ("viscous", "coulomb")), arm3, q, qd, qdd)
    np.testing.assert_array_equal(F[:, :, 10 * n :], cols)


def test_term_columns_are_the_torque_each_parameter_adds(arm3):
    _, q, qd, qdd = states(arm3)
    j = 1
    region = Region("q.joint2", 0.2, 0.9)
    pf = columns(make_term("position_friction", "joint2", region=region), arm3, q, qd, qdd)
    inside = (q[:, j] >= 0.2) & (q[:, j] <= 0.9)
    np.testing.assert_array_equal(pf[:, j, 0], inside * np.sign(qd[:, j]))
    np.testing.assert_array_equal(pf[:, j, 1], inside * qd[:, j])
    assert not pf[:, [0, 2]].any()  # only its joint
    spring = columns(make_term("spring", "joint2", {"rest_angle": 0.3}), arm3, q, qd, qdd)
    np.testing.assert_allclose(spring[:, j, 0], q[:, j] - 0.3)
    # a file written before the rest angle was a parameter: its origin in extra, its rest angle 0
    old = term_from_dict({"cause": "spring", "channel": "joint2", "extra": {"reference": 0.3},
                          "parameters": {"stiffness": {"value": 2.0, "stderr": 0.1}}})
    assert old.value("rest_angle") == 0.0
    np.testing.assert_allclose(columns(old, arm3, q, qd, qdd)[:, j, 0], q[:, j] - 0.3)
    arm = columns(make_term("armature", "joint3"), arm3, q, qd, qdd)
    np.testing.assert_array_equal(arm[:, 2, 0], qdd[:, 2])
    coupled = make_term("coupled_friction", "joint3", {"smoothing": 0.05}, extra={"partner": "joint2", "ratio": 2.0})
    cf = columns(coupled, arm3, q, qd, qdd)
    v = qd[:, 2] + 2.0 * qd[:, 1]
    np.testing.assert_allclose(cf[:, 2, 0], np.tanh(v / 0.05))  # the motor's Coulomb friction, smoothed
    np.testing.assert_allclose(cf[:, 1, 1], 2.0 * v)  # the partner feels ratio × the motor's friction


def test_a_coupled_friction_written_before_its_smoothing_reads_as_a_sign(arm3):
    """A file whose coupled_friction has only coulomb and viscous (written before the smoothing was
    a parameter) means a Coulomb part that switches with the motor's sign: smoothing 1e-4 rad/s."""
    _, q, qd, qdd = states(arm3)
    d = make_term("coupled_friction", "joint3", {"coulomb": 0.2, "viscous": 0.1},
                  extra={"partner": "joint2", "ratio": 1.0}).to_dict()
    del d["parameters"]["smoothing"]
    old = term_from_dict(d, domain="dynamics")
    assert old.value("smoothing") == MIN_SMOOTHING and old.value("coulomb") == 0.2
    v = qd[:, 2] + qd[:, 1]
    moving = np.abs(v) > 1e-2
    np.testing.assert_allclose(columns(old, arm3, q, qd, qdd)[moving, 2, 0], np.sign(v[moving]))
    del d["parameters"]["viscous"]  # a parameter that always existed is still required
    with pytest.raises(InputFileError, match="has parameters"):
        term_from_dict(d, domain="dynamics")


def test_terms_round_trip_through_yaml_and_refuse_bad_input():
    t = make_term("position_friction", "joint2", {"coulomb": 0.3}, region=Region("q.joint2", 0.2, 0.9))
    back = term_from_dict(t.to_dict())
    assert back == t and back.value("coulomb") == 0.3
    # every dynamics term of the registry has a behaviour here (the sensor causes are filters, a
    # backlash a filter of the angles)
    assert set(COLUMNS) | set(FILTERS) | {BACKLASH} == set(causes_of("dynamics", "term"))
    with pytest.raises(InputFileError, match="not a dynamics term"):
        columns(make_term("backlash", "joint1"), None, np.zeros((2, 3)), np.zeros((2, 3)), np.zeros((2, 3)))
    with pytest.raises(InputFileError, match="is a kinematics cause"):
        term_from_dict(make_term("backlash", "joint1").to_dict(), domain="dynamics")
    with pytest.raises(InputFileError, match="needs a region"):
        make_term("position_friction", "joint1")
    with pytest.raises(InputFileError, match="has parameters"):
        term_from_dict({"cause": "torque_offset", "channel": "joint1", "parameters": {"bias": 1.0}})


def test_lag_filter_is_a_first_order_sensor():
    t = np.arange(0, 3, 0.01)
    x = 0.5 * t  # a ramp: a first-order lag L follows it L seconds late once settled
    y = lag_filter(x, t, 0.05)
    np.testing.assert_allclose(y[100:], 0.5 * (t[100:] - 0.05), atol=1e-9)
    assert lag_filter(x, t, 0.0) is not x and np.array_equal(lag_filter(x, t, 0.0), x)
    # a gap restarts it at rest
    t2 = np.concatenate([t, t + 10.0])
    y2 = lag_filter(np.concatenate([x, x]), t2, 0.05)
    np.testing.assert_allclose(y2[t.size :], y, atol=1e-12)


def test_a_model_with_extra_terms_recovers_them_and_predicts_with_a_lag(arm3, tmp_path):
    time, q, qd, qdd = states(arm3, T=1500, seed=1)
    base = DynamicsModel(arm3, SGPOptions(kind="pr"))
    base.fit_arrays(q, qd, qdd, np.zeros((len(q), 3)) + 1e-3 * np.random.default_rng(0).standard_normal((len(q), 3)))
    w_true = np.random.default_rng(2).normal(size=base.base_.n_base)
    F = base.features(q, qd, qdd)
    offset = make_term("torque_offset", "joint3")
    lag = make_term("torque_lag", "joint2", values={"lag": 0.03})
    tau = F @ w_true
    tau[:, 2] += 0.4  # the offset
    tau[:, 1] = lag_filter(tau[:, 1], time, 0.03)
    tau += 1e-3 * np.random.default_rng(3).standard_normal(tau.shape)
    model = DynamicsModel(arm3, SGPOptions(kind="pr"), terms=(offset, lag))
    model.fit_arrays(q, qd, qdd, tau, time=time)
    fitted = {t.cause: t for t in model.fitted_terms()}
    assert fitted["torque_offset"].value("offset") == pytest.approx(0.4, abs=0.01)
    assert fitted["torque_lag"].value("lag") == 0.03  # fixed as given
    assert model.parameter_names[-1].startswith("torque_offset:joint3")
    pred = model.predict_arrays(q, qd, qdd, time).tau
    assert np.sqrt(np.mean((pred - tau) ** 2)) < 3e-3
    # saved and loaded: same prediction, terms listed with their values
    save_model(model, tmp_path / "m.sgp", {"log": "x"})
    back = load_model(tmp_path / "m.sgp")
    assert [t.cause for t in back.terms] == ["torque_offset", "torque_lag"]
    np.testing.assert_allclose(back.predict_arrays(q, qd, qdd, time).tau, pred, atol=1e-9)
    # without terms the model is the one it always was: no 'terms' in its sgp.yaml
    save_model(base, tmp_path / "b.sgp")
    assert "terms" not in (tmp_path / "b.sgp" / "sgp.yaml").read_text()
    assert load_model(tmp_path / "b.sgp").terms == ()


def test_a_gain_term_scales_its_joints_columns_with_or_without_time(arm3, tmp_path):
    time, q, qd, qdd = states(arm3, T=1500, seed=1)
    base = DynamicsModel(arm3, SGPOptions(kind="pr"))
    base.fit_arrays(q, qd, qdd, 1e-3 * np.random.default_rng(0).standard_normal((len(q), 3)))
    tau = base.features(q, qd, qdd) @ np.random.default_rng(2).normal(size=base.base_.n_base)
    tau[:, 1] *= 1.2  # joint2's sensor reads 20 % high
    tau += 1e-3 * np.random.default_rng(3).standard_normal(tau.shape)
    gain = make_term("torque_gain", "joint2", values={"gain_error": 0.2})
    model = DynamicsModel(arm3, SGPOptions(kind="pr"), terms=(gain,))
    model.fit_arrays(q, qd, qdd, tau)  # a gain needs no time
    assert model.fitted_terms()[0].value("gain_error") == 0.2  # held as given
    assert model.parameter_names == tuple(base.base_.names)  # no columns of its own
    pred = model.predict_arrays(q, qd, qdd).tau
    assert np.sqrt(np.mean((pred - tau) ** 2)) < 3e-3
    np.testing.assert_allclose(model.mean_in_chunks(q, qd, qdd, time), pred, atol=1e-9)
    save_model(model, tmp_path / "g.sgp", {"log": "x"})
    np.testing.assert_allclose(load_model(tmp_path / "g.sgp").predict_arrays(q, qd, qdd).tau, pred, atol=1e-9)
    # the same model without the gain misses joint2 by the gain's share of its torque
    plain = DynamicsModel(arm3, SGPOptions(kind="pr")).fit_arrays(q, qd, qdd, tau)
    assert np.sqrt(np.mean((plain.predict_arrays(q, qd, qdd).tau - tau) ** 2)) > 10 * 3e-3


def test_a_lag_term_needs_the_samples_time(arm3):
    _, q, qd, qdd = states(arm3, T=200)
    model = DynamicsModel(arm3, SGPOptions(kind="pr"), terms=(make_term("torque_lag", "joint1", values={"lag": 0.01}),))
    with pytest.raises(Exception, match="time"):
        model.fit_arrays(q, qd, qdd, np.zeros((200, 3)))


def test_payload_columns_are_the_link_bodys_ten_inertial_columns(arm3):
    """A payload's columns are the regressor's block of its link's body: a point mass m at lever c
    (second moments m(|c|²I − ccᵀ) about the joint frame) adds exactly columns @ its parameters."""
    import pinocchio as pin

    _, q, qd, qdd = states(arm3, T=50)
    term = make_term("payload", "link3")
    assert [p.name for p in term.parameters][:4] == ["mass", "mc_x", "mc_y", "mc_z"]
    X = columns(term, arm3, q, qd, qdd)
    assert X.shape == (50, 3, 10)
    n = arm3.n_joints
    np.testing.assert_array_equal(X, full_regressor(arm3, q, qd, qdd, ())[:, :, 10 * (n - 1) : 10 * n])
    c = np.array([0.2, 0.03, -0.02])
    theta = pin.Inertia(0.7, c, np.zeros((3, 3))).toDynamicParameters()
    heavy = arm3.model.copy()
    heavy.inertias[n] += pin.Inertia(0.7, c, np.zeros((3, 3)))
    d0, d1 = arm3.model.createData(), heavy.createData()
    diff = np.array([pin.rnea(heavy, d1, *x) - pin.rnea(arm3.model, d0, *x) for x in zip(q, qd, qdd, strict=True)])
    np.testing.assert_allclose(X @ theta, diff, atol=1e-10)
    with pytest.raises(InputFileError, match="moving link"):
        columns(make_term("payload", "no_such_link"), arm3, q, qd, qdd)


def test_a_nominal_inertia_model_fits_friction_and_a_payload_and_survives_its_bundle(arm3, tmp_path):
    """inertia="nominal": the URDF's rigid body is a fixed part of the prediction (rnea), W holds
    the friction and the extra terms only; saved and loaded it predicts the same; the default
    options' summary has no 'inertia' key (default fits unchanged), a bad value is refused."""
    import pinocchio as pin

    from diegocal.sgp.model import nominal_torque

    time, q, qd, qdd = states(arm3, T=1500, seed=4)
    data = arm3.model.createData()
    rnea = np.array([pin.rnea(arm3.model, data, *x) for x in zip(q, qd, qdd, strict=True)])
    np.testing.assert_allclose(nominal_torque(arm3, q, qd, qdd), rnea, atol=1e-9)
    payload = make_term("payload", "link3")
    theta = pin.Inertia(0.4, np.array([0.1, 0.0, 0.02]), np.zeros((3, 3))).toDynamicParameters()
    tau = rnea + columns(payload, arm3, q, qd, qdd) @ theta + 0.3 * qd + 0.1 * np.sign(qd)
    tau += 1e-3 * np.random.default_rng(5).standard_normal(tau.shape)
    opts = SGPOptions(kind="pr", inertia="nominal")
    model = DynamicsModel(arm3, opts, terms=(payload,)).fit_arrays(q, qd, qdd, tau, time=time)
    assert model.base_.n_base == 2 * arm3.n_joints  # friction only
    assert model.fitted_terms()[0].value("mass") == pytest.approx(0.4, abs=0.01)
    pred = model.predict_arrays(q, qd, qdd, time)
    assert np.sqrt(np.mean((pred.tau - tau) ** 2)) < 3e-3
    save_model(model, tmp_path / "n.sgp", {"log": "x"})
    assert "inertia: nominal" in (tmp_path / "n.sgp" / "sgp.yaml").read_text()
    back = load_model(tmp_path / "n.sgp")
    assert back.options.inertia == "nominal"
    np.testing.assert_allclose(back.predict_arrays(q, qd, qdd, time).tau, pred.tau, atol=1e-9)
    # without the payload term the nominal model cannot explain it; an identified one absorbs it
    bare = DynamicsModel(arm3, opts).fit_arrays(q, qd, qdd, tau)
    ident = DynamicsModel(arm3, SGPOptions(kind="pr")).fit_arrays(q, qd, qdd, tau)
    err = [np.sqrt(np.mean((m.predict_arrays(q, qd, qdd).tau - tau) ** 2)) for m in (bare, ident)]
    assert err[0] > 10 * err[1], err
    assert "inertia" not in SGPOptions().to_dict()
    with pytest.raises(ValueError, match="inertia"):
        SGPOptions(inertia="guessed")


def test_a_shape_parameter_is_held_by_the_model_and_kept_with_its_term(arm3, tmp_path):
    """stribeck_friction: amplitude · sign(qd) · e^(−|qd|/scale); its velocity scale is a shape
    parameter (no column of its own): the model fits the amplitude with W and keeps the scale as
    given, through the bundle too."""
    time, q, qd, qdd = states(arm3, T=1500, seed=4)
    term = make_term("stribeck_friction", "joint2", {"velocity_scale": 0.05})
    assert [p.name for p in term.linear] == ["amplitude"] and columns(term, arm3, q, qd, qdd).shape[-1] == 1
    col = np.sign(qd[:, 1]) * np.exp(-np.abs(qd[:, 1]) / 0.05)
    np.testing.assert_allclose(columns(term, arm3, q, qd, qdd)[:, 1, 0], col)
    base = DynamicsModel(arm3, SGPOptions(kind="pr"))
    base.fit_arrays(q, qd, qdd, np.zeros((len(q), 3)) + 1e-3 * np.random.default_rng(0).standard_normal((len(q), 3)))
    w_true = np.random.default_rng(5).normal(size=base.base_.n_base)
    tau = base.features(q, qd, qdd) @ w_true
    tau[:, 1] += -0.3 * col
    tau += 1e-3 * np.random.default_rng(6).standard_normal(tau.shape)
    model = DynamicsModel(arm3, SGPOptions(kind="pr"), terms=(term,)).fit_arrays(q, qd, qdd, tau)
    (fitted,) = model.fitted_terms()
    assert fitted.value("velocity_scale") == 0.05  # held as given
    amp = fitted.parameters[0]
    assert abs(amp.value + 0.3) < 4 * amp.stderr and amp.stderr < 0.01
    save_model(model, tmp_path / "s.sgp")
    (back,) = load_model(tmp_path / "s.sgp").fitted_terms()
    assert back.value("velocity_scale") == 0.05 and back.value("amplitude") == pytest.approx(amp.value)
