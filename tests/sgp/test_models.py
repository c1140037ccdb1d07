"""PR, GP, PRGP and SGP against simulator ground truth, on held-out data; save/load; sparse."""

from dataclasses import replace

import numpy as np
import pytest

from diegocal.io import load_yaml, save_yaml
from diegocal.sgp import DynamicsModel, SGPOptions, fit_dynamics, load_model, nmse
from diegocal.sgp.store import save_model

BUMP = (1, 0.0, 1.2, 1.5)  # extra viscous friction on the elbow for q ∈ (0, 1.2) rad: unmodelled


@pytest.fixture(scope="module")
def case(arm2, simulate):
    """Training log, held-out log (another excitation) and its noise-free torques, with a bump."""
    train, _ = simulate(arm2, T=250, seed=0, bump=BUMP)
    test, clean = simulate(arm2, T=250, seed=1, bump=BUMP)
    return train, test, clean


@pytest.fixture(scope="module")
def fitted(arm2, case):
    """fitted(name) -> model, fitted once per module (pr, gp, prgp, sgp, sgp-noguard)."""
    cache = {}
    options = {
        "pr": SGPOptions(kind="pr"),
        "gp": SGPOptions(kind="gp"),
        "prgp": SGPOptions(kind="prgp"),
        "sgp": SGPOptions(kind="sgp"),
        "sgp-noguard": SGPOptions(kind="sgp", guard=False),
    }

    def get(name):
        if name not in cache:
            cache[name] = fit_dynamics(case[0], arm2, options[name])
        return cache[name]

    return get


def test_sgp_beats_pr_on_held_out_data_with_an_unmodelled_effect(case, fitted):
    _, test, clean = case
    pr, sgp = fitted("pr").predict(test), fitted("sgp").predict(test)
    e_pr, e_sgp = nmse(pr.tau, clean), nmse(sgp.tau, clean)
    assert e_sgp[1] < 0.5 * e_pr[1], (e_pr, e_sgp)  # the elbow, where the bump acts
    assert e_sgp[0] < 1.5 * e_pr[0] + 1e-3  # and no worse on the shoulder
    # roughly calibrated uncertainty: measured torques inside ±2σ (nominally 95 %); the elbow's
    # bump has two steps in q, the default guard cuts the GP at one of them (Guard.joint_region:
    # nMSE 0.030 against 0.049 without the cut), and its interval is somewhat too narrow there
    # on held-out data (89 %; 95 % without the cut)
    measured = test.stream("tau").data
    inside = np.mean(np.abs(sgp.tau - measured) <= 2 * sgp.tau_std, axis=0)
    assert inside[0] > 0.9 and inside[1] > 0.8 and np.all(inside <= 1.0), inside
    assert np.all(sgp.tau_std > sgp.tau_std_latent)


@pytest.mark.parametrize("kind", ["gp", "prgp"])
def test_baselines_predict_held_out_data(case, fitted, kind):
    _, test, clean = case
    model = fitted(kind)
    pred = model.predict(test)
    assert pred.tau.shape == clean.shape and np.all(pred.tau_std > 0)
    assert (model.parametric_ is None) == (kind == "gp")
    err = nmse(pred.tau, clean)
    if kind == "gp":  # no physics: fine where the data are, clearly worse than the SGP
        assert np.all(err < 0.3)
    else:
        # two stages (thesis §3.4.1): the GP on PR's residuals cannot undo PR's bias on a new
        # trajectory, and its ML-II optimum is start-dependent (a 1e-9 change of the start moves
        # it), so it is only asked to stay near PR, while the joint fit (SGP) must beat it where
        # the unmodelled bump acts (the elbow)
        e_pr = nmse(fitted("pr").predict(test).tau, clean)
        assert np.all(err <= 1.2 * e_pr + 1e-4), (err, e_pr)
        assert nmse(fitted("sgp").predict(test).tau, clean)[1] < 0.8 * err[1]


def test_uncertainty_grows_away_from_the_training_data(case, fitted):
    """Thesis §3.5.1: the SGP knows that it does not know."""
    train = case[0]
    model = fitted("sgp-noguard")
    q, qd, qdd = (train.stream(s).data[:50] for s in ("q", "qd", "qdd"))
    near = model.predict_arrays(q, qd, qdd).tau_std_latent
    far = model.predict_arrays(q, qd + 8.0, qdd).tau_std_latent  # velocities never seen
    assert np.all(far.mean(0) > 2 * near.mean(0))


@pytest.mark.parametrize("kind", ["sgp", "prgp"])
def test_save_load_round_trip(case, fitted, tmp_path, kind):
    test = case[1]
    model = fitted(kind)
    save_model(model, tmp_path / "m.sgp", meta={"log": "train.h5"})
    back = load_model(tmp_path / "m.sgp")
    a, b = model.predict(test), back.predict(test)
    np.testing.assert_allclose(b.tau, a.tau, rtol=1e-9, atol=1e-10)
    np.testing.assert_allclose(b.tau_std, a.tau_std, rtol=1e-9, atol=1e-10)
    assert back.hyperparameters_ == model.hyperparameters_


def test_sparse_close_to_exact_on_the_same_data(arm2, case, fitted, tmp_path):
    train, test, clean = case
    exact = fitted("sgp")
    # auto switches to sparse above exact_max: same hyperparameters, DTC posterior (150 inducing)
    opts = SGPOptions(kind="sgp", inference="auto", exact_max=100, n_inducing=150)
    arrays = [train.stream(s).data for s in ("q", "qd", "qdd", "tau")]
    state = {"base": exact.base_.to_dict(), "hyper": exact.gp_.hyper_}
    sparse = DynamicsModel(arm2, opts).fit_arrays(*arrays, state=state)
    assert exact.gp_.inference == "exact" and sparse.gp_.inference == "sparse"
    e_exact = nmse(exact.predict(test).tau, clean)
    e_sparse = nmse(sparse.predict(test).tau, clean)
    assert np.all(e_sparse < 1.5 * e_exact + 2e-3), (e_exact, e_sparse)
    save_model(sparse, tmp_path / "s.sgp")
    back = load_model(tmp_path / "s.sgp").predict(test)
    np.testing.assert_allclose(back.tau, sparse.predict(test).tau, rtol=1e-8, atol=1e-9)


def test_guard_switches_gp_inputs_and_bounds(case, fitted):
    from diegocal.sgp.kernels import RELEASED_LENGTHSCALE
    from diegocal.sgp.model import MAX_LENGTHSCALE

    train = case[0]
    on, off = fitted("sgp"), fitted("sgp-noguard")
    ell_on = on.hyperparameters_["elbow"]["lengthscales"]
    ell_off = off.hyperparameters_["elbow"]["lengthscales"]
    assert not any(k.startswith("qdd.") for k in ell_on)
    assert any(k.startswith("qdd.") for k in ell_off)
    # length-scales within MAX_LENGTHSCALE training stds of their input; the GP judged against a
    # parametric-only fallback on held-out samples
    names = [f"{s}.{j}" for s in ("q", "qd") for j in ("shoulder", "elbow")]
    std = dict(zip(names, np.hstack([train.stream("q").data, train.stream("qd").data]).std(0), strict=True))
    # (a released input's is constant: RELEASED_LENGTHSCALE stds)
    choices = set()
    for joint in ("shoulder", "elbow"):
        choices.add(on.hyperparameters_[joint]["guard_choice"])
        for name, ell in on.hyperparameters_[joint]["lengthscales"].items():
            released = np.isclose(ell, RELEASED_LENGTHSCALE * std[name], rtol=1e-9)
            assert ell <= MAX_LENGTHSCALE * std[name] * (1 + 1e-9) or released
    assert choices <= {"learnt", "released", "cut", "parametric"}  # cut: the elbow's bump (Guard.joint_region)
    assert on.gp_.n_starts_ == 3 and set(on.gp_.validation_scores_) >= {"learnt", "parametric"}
    assert off.gp_.n_starts_ == 3 and not hasattr(off.gp_, "validation_scores_")
    explicit = replace(SGPOptions(kind="sgp", guard=False), gp_inputs=("q",))
    assert explicit.resolved_gp_inputs() == ("q",)


def test_bad_options_raise():
    with pytest.raises(ValueError, match="unknown model kind"):
        SGPOptions(kind="nn")
    with pytest.raises(ValueError, match="friction"):
        SGPOptions(friction=("stiction",))


def _drop_tau(log, keep):
    from diegocal.io import Log, make_stream

    tau = log.stream("tau")
    streams = dict(log.streams, tau=make_stream(list(keep), tau.select(list(keep)).data))
    return Log(log.time, streams, robot=log.robot)


@pytest.mark.parametrize("kind", ["pr", "sgp"])
def test_joints_without_a_torque_are_left_out_of_the_fit(arm2, case, tmp_path, caplog, kind):
    """TIAGo's wrists: no usable torque. The other joints' rows are fitted (every joint's motion
    still enters them); predictions and saved models cover the fitted joints only."""
    train, test, clean = case
    with caplog.at_level("WARNING", logger="diegocal.sgp.model"):
        model = fit_dynamics(_drop_tau(train, ["elbow"]), arm2, SGPOptions(kind=kind))
    assert "shoulder" in caplog.text and "elbow" in caplog.text
    assert model.joint_names == ("elbow",) and model.joints_without_tau == ("shoulder",)
    full = fit_dynamics(train, arm2, SGPOptions(kind="pr"))
    assert model.base_.n_base < full.base_.n_base  # the shoulder's own parameters drop out
    pred = model.predict(test)
    assert pred.tau.shape == (len(clean), 1)
    # the elbow row alone identifies what it needs: as good as the all-joint PR on the elbow
    e_full = nmse(full.predict(test).tau, clean)[1]
    assert nmse(pred.tau, clean[:, 1:])[0] < max(1.5 * e_full, 0.05)
    save_model(model, tmp_path / "m.sgp")
    back = load_model(tmp_path / "m.sgp")
    assert back.joint_names == ("elbow",)
    np.testing.assert_allclose(back.predict(test).tau, pred.tau, rtol=1e-9, atol=1e-10)


def test_a_torque_stream_with_no_joint_of_the_robot_is_an_error(arm2, case):
    from diegocal.errors import DiegocalError
    from diegocal.io import Log, make_stream

    train = case[0]
    streams = dict(train.streams, tau=make_stream(["wrist"], train.stream("tau").data[:, :1]))
    with pytest.raises(DiegocalError, match="wrist"):
        fit_dynamics(Log(train.time, streams, robot=train.robot), arm2, SGPOptions(kind="pr"))


def test_an_edited_guard_validation_entry_is_left_out_on_load(fitted, tmp_path):
    """sgp.yaml's guard_validation is reporting only: a hand-edited entry that is not a map of
    numbers does not stop the model from loading and predicting; well-formed, it is restored."""
    model = fitted("sgp")
    path = tmp_path / "m.sgp"
    save_model(model, path, meta={"log": "train.h5"})
    assert load_model(path).hyperparameters_ == model.hyperparameters_
    summary = load_yaml(path / "sgp.yaml")
    joint = model.joint_names[0]
    summary["hyperparameters"][joint]["guard_validation"] = {"learnt": "oops"}
    save_yaml(summary, path / "sgp.yaml")
    back = load_model(path)
    assert "guard_validation" not in back.hyperparameters_[joint]
    assert back.hyperparameters_[joint]["guard_choice"] == model.hyperparameters_[joint]["guard_choice"]


def test_base_parameters_that_trade_off_are_written_next_to_each_other(fitted, tmp_path, monkeypatch):
    """sgp.yaml writes ``correlated: {CHANNEL.NAME: ρ}`` beside each baseline parameter whose
    estimate correlates with another's by 0.9 or more (here one rigid-body parameter and one
    joint's viscous friction, their covariance set so), both ways, and nothing else."""
    model = fitted("pr")
    par = model.parametric_
    names = list(par.names)
    i = next(k for k, n in enumerate(names[: model.base_.n_base]) if "friction" not in n)
    j = next(k for k, n in enumerate(names[: model.base_.n_base]) if n.startswith("viscous_friction:"))
    cov = np.diag(np.diag(par.cov))
    cov[i, j] = cov[j, i] = -0.95 * np.sqrt(cov[i, i] * cov[j, j])
    monkeypatch.setattr(type(model), "parametric_", property(lambda _: replace(par, cov=cov)))
    save_model(model, tmp_path / "m.sgp")
    written = {}
    for term in load_yaml(tmp_path / "m.sgp" / "sgp.yaml")["baseline"]:
        for name, p in term["parameters"].items():
            if "correlated" in p:
                written[f"{term['channel']}.{name}"] = p["correlated"]
    joint = names[j].partition(":")[2].partition(".")[0]
    rigid = f"{model.robot.name}.{names[i]}"
    assert written == {rigid: {f"{joint}.viscous": -0.95}, f"{joint}.viscous": {rigid: -0.95}}
