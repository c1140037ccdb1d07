"""`diegocal sgp-fit` and `diegocal predict sgp/`: end to end, and one-line errors on bad input."""

import numpy as np
import pytest
from typer.testing import CliRunner

from diegocal.cli import app
from diegocal.cli.testing import one_line_error
from diegocal.io import Log, load_log, load_yaml, make_stream, save_log
from diegocal.sgp.store import parameters_of

runner = CliRunner()


@pytest.fixture
def logs(arm2, simulate, tmp_path):
    train, _ = simulate(arm2, T=120, seed=0)
    test, _ = simulate(arm2, T=60, seed=1)
    paths = tmp_path / "train.h5", tmp_path / "test.h5"
    save_log(train, paths[0])
    save_log(test, paths[1])
    return paths


def test_fit_and_predict_end_to_end(logs, arm2_dir):
    train, test = logs
    r = runner.invoke(app, ["sgp-fit", str(train), "--robot", str(arm2_dir), "-m", "pr", "-q"])
    assert r.exit_code == 0, r.output
    model_dir = train.with_name("train.sgp")  # DESIGN.md default: <log stem>.sgp/
    summary = load_yaml(model_dir / "sgp.yaml")
    assert summary["kind"] == "dynamics" and summary["robot"]["name"] == "arm2"  # the bundle header
    assert summary["model_kind"] == "pr" and set(summary["meta"]) == {
        "log",
        "robot",
        "command",
        "created",
    }
    assert set(summary["nmse_in_sample"]) == {"shoulder", "elbow"}
    assert all(v < 0.05 for v in summary["nmse_in_sample"].values())
    out = test.with_name("pred.h5")
    r = runner.invoke(app, ["predict", str(model_dir), str(test), "-o", str(out)])
    assert r.exit_code == 0, r.output
    assert "nMSE shoulder" in r.output
    pred = load_log(out)
    assert pred.stream("tau").data.shape == (60, 2) and np.all(pred.stream("tau_std").data > 0)
    measured = load_log(test).stream("tau").data
    err = np.mean((pred.stream("tau").data - measured) ** 2, 0) / np.var(measured, 0)
    assert np.all(err < 0.05)


def test_sgp_fit_writes_hyperparameters(logs, arm2_dir, tmp_path):
    train, _ = logs
    out = tmp_path / "m.sgp"
    args = ["sgp-fit", str(train), "--robot", str(arm2_dir), "--friction", "none", "-o", str(out)]
    r = runner.invoke(app, args + ["--min-noise", "0.05"])
    assert r.exit_code == 0, r.output
    s = load_yaml(out / "sgp.yaml")
    assert s["model_kind"] == "sgp" and s["options"]["friction"] == [] and s["options"]["min_noise"] == 0.05
    assert "lengthscales" in s["hyperparameters"]["elbow"]
    # the guard's cross-validated choice per joint, in the summary and the file
    for joint in ("shoulder", "elbow"):
        choice = s["hyperparameters"][joint]["guard_choice"]
        assert choice in ("learnt", "released", "extended", "two-stage", "parametric") and f"guard {joint}" in r.output
        # and the cross-validated nMSE of every candidate it weighed, the chosen one among them
        weighed = s["hyperparameters"][joint]["guard_validation"]
        assert {choice, "parametric"} <= set(weighed) and all(v > 0 for v in weighed.values())
        assert s["hyperparameters"][joint]["sigma_v"] >= 0.05 * 0.999 * np.std(
            load_log(train).stream("tau").data[:, ["shoulder", "elbow"].index(joint)]
        )
    assert not any("friction" in n for n in parameters_of(s))
    assert r.output.count("cross-validated nMSE") == 2


def _without(log, stream):
    return Log(log.time, {k: v for k, v in log.streams.items() if k != stream}, robot=log.robot)


@pytest.mark.parametrize("stream", ["tau", "qdd"])
def test_missing_stream_is_named(arm2, simulate, arm2_dir, tmp_path, stream):
    log, _ = simulate(arm2, T=30, seed=0)
    path = tmp_path / "bad.h5"
    save_log(_without(log, stream), path)
    line = one_line_error(runner.invoke(app, ["sgp-fit", str(path), "--robot", str(arm2_dir)]))
    assert f"'{stream}'" in line and "sgp-fit" in line


def test_joint_not_in_robot(arm2, simulate, arm2_dir, tmp_path):
    log, _ = simulate(arm2, T=30, seed=0)
    renamed = {k: make_stream(["shoulder", "wrist"], v.data) for k, v in log.streams.items()}
    path = tmp_path / "bad.h5"
    save_log(Log(log.time, renamed), path)
    res = runner.invoke(app, ["sgp-fit", str(path), "--robot", str(arm2_dir), "-o", str(tmp_path / "m.sgp")])
    # a channel that is no joint of the robot (a gripper's motor) is left out, said in one warning (30
    # samples also leave a parameter held by the prior: another warning)
    warnings = [ln for ln in res.output.splitlines() if ln.startswith("warning:") and "held by the prior" not in ln]
    assert res.exit_code == 0 and len(warnings) == 1 and "wrist" in warnings[0] and "not joints" in warnings[0]


def test_too_few_samples(arm2, simulate, arm2_dir, tmp_path):
    log, _ = simulate(arm2, T=5, seed=0)
    path = tmp_path / "short.h5"
    save_log(log, path)
    line = one_line_error(runner.invoke(app, ["sgp-fit", str(path), "--robot", str(arm2_dir)]))
    assert "too few samples" in line


@pytest.mark.parametrize(
    ("option", "value", "needle"),
    [
        ("--model", "nn", "--model"),
        ("--friction", "stiction", "--friction"),
        ("--inference", "magic", "--inference"),
        ("--gp-inputs", "tau", "--gp-inputs"),
        ("--min-noise", "-0.1", "--min-noise"),
    ],
)
def test_bad_option_values(logs, arm2_dir, option, value, needle):
    train, _ = logs
    r = runner.invoke(app, ["sgp-fit", str(train), "--robot", str(arm2_dir), option, value])
    assert needle in one_line_error(r)


def test_log_without_robot_needs_robot_option(arm2, simulate, tmp_path):
    log, _ = simulate(arm2, T=30, seed=0)
    path = tmp_path / "anon.h5"
    save_log(Log(log.time, log.streams), path)
    assert "--robot" in one_line_error(runner.invoke(app, ["sgp-fit", str(path)]))


def test_predict_with_a_directory_that_is_not_a_model(logs, tmp_path):
    _, test = logs
    empty = tmp_path / "empty.sgp"
    empty.mkdir()
    assert "sgp.yaml" in one_line_error(runner.invoke(app, ["predict", str(empty), str(test)]))


def test_fit_and_predict_when_a_joint_has_no_torque(arm2, simulate, arm2_dir, tmp_path):
    log, _ = simulate(arm2, T=120, seed=0)
    streams = dict(log.streams, tau=make_stream(["elbow"], log.stream("tau").select(["elbow"]).data))
    path = tmp_path / "wrist.h5"
    save_log(Log(log.time, streams, robot=log.robot), path)
    out = tmp_path / "w.sgp"
    r = runner.invoke(app, ["sgp-fit", str(path), "--robot", str(arm2_dir), "-m", "pr", "-o", str(out)])
    assert r.exit_code == 0, r.output
    assert "not fitted (no tau)" in r.output and "shoulder" in r.output
    summary = load_yaml(out / "sgp.yaml")
    assert summary["joints"] == ["elbow"] and summary["joints_without_tau"] == ["shoulder"]
    pred_path = tmp_path / "pred.h5"
    r = runner.invoke(app, ["predict", str(out), str(path), "-o", str(pred_path)])
    assert r.exit_code == 0, r.output
    pred = load_log(pred_path)
    assert pred.stream("tau").names == ("elbow",) and pred.stream("q").names == ("shoulder", "elbow")


def test_predict_warns_when_the_torques_fall_outside_the_two_sigma_band_too_often(logs, arm2_dir):
    """A test log whose elbow torque is off by a constant the model cannot know: the summary's
    coverage falls below 0.85 and one warning line names the joint; the shoulder is not named."""
    train, test = logs
    r = runner.invoke(app, ["sgp-fit", str(train), "--robot", str(arm2_dir), "-m", "pr", "-q"])
    assert r.exit_code == 0, r.output
    model_dir = train.with_name("train.sgp")
    r = runner.invoke(app, ["predict", str(model_dir), str(test), "-q"])
    assert r.exit_code == 0 and "warning" not in r.output, r.output  # calibrated: no warning
    log = load_log(test)
    tau = log.stream("tau")
    shifted = tau.data + np.array([0.0, 5.0 * tau.data[:, 1].std()])
    drifted = test.with_name("drifted.h5")
    save_log(Log(log.time, {**log.streams, "tau": make_stream(tau.names, shifted)}, robot=log.robot), drifted)
    r = runner.invoke(app, ["predict", str(model_dir), str(drifted), "-q"])
    assert r.exit_code == 0, r.output
    warnings = [line for line in r.output.splitlines() if line.startswith("warning")]
    assert len(warnings) == 1 and "below 0.85 on elbow" in warnings[0] and "shoulder" not in warnings[0], r.output


def test_sgp_fit_region_and_joint_cut_are_the_default_and_their_off_switches_are_recorded(logs, arm2_dir, tmp_path):
    """Guard.region and Guard.joint_region are on by default: the reloaded model rebuilds the
    estimator with the joints' angles as region inputs and its joint GPs as Region kernels on
    them, and predicts exactly as the fitted one; `--no-region` and `--no-joint-region` are
    written to sgp.yaml's guard options and reload without them. (Nothing is cut on this short
    log; a model that chose the joint cut is saved and reloaded in
    tests/sgp/test_joint_region_slow.py.)"""
    from diegocal.robot import load_robot
    from diegocal.sgp import fit_dynamics
    from diegocal.sgp.kernels import Region
    from diegocal.sgp.store import load_model

    def fit(name, *flags):
        out = tmp_path / name
        r = runner.invoke(app, ["sgp-fit", str(train), "--robot", str(arm2_dir), *flags, "-q", "-o", str(out)])
        assert r.exit_code == 0, r.output
        return out, load_model(out), load_yaml(out / "sgp.yaml")["options"]["guard_options"]

    def region_dims(model):
        return [k.dim for k in model.gp_.kernels if isinstance(k, Region)]

    train, test = logs
    out, model, _ = fit("r.sgp")
    assert model.gp_.region_inputs == (0, 1)  # q.shoulder, q.elbow
    assert region_dims(model) == [0, 1]
    fitted = fit_dynamics(load_log(train), load_robot(arm2_dir), model.options)
    np.testing.assert_allclose(model.predict(load_log(test)).tau, fitted.predict(load_log(test)).tau, rtol=1e-9)
    _, off, guard = fit("n.sgp", "--no-region")
    assert guard["region"] is False and off.gp_.region_inputs is None and region_dims(off) == []
    _, joint_off, guard = fit("j.sgp", "--no-joint-region")
    assert guard["region"] is True and guard["joint_region"] is False
    assert joint_off.gp_.region_inputs == (0, 1) and region_dims(joint_off) == []
    r = runner.invoke(app, ["predict", str(out), str(test), "-q", "-o", str(tmp_path / "p.h5")])
    assert r.exit_code == 0, r.output


def test_the_coverage_warning_names_the_joints_out_of_range_to_three_digits():
    """0.9931 is above 0.99: printed as 0.99 the warning would contradict itself."""
    from diegocal.predict import coverage_warnings

    (text,) = coverage_warnings(["joint1", "joint2", "joint3"], [0.9931, 0.95, 0.8])
    assert "above 0.99 on joint1 0.993" in text and "below 0.85 on joint3 0.800" in text, text
    assert "joint2" not in text
    assert coverage_warnings(["joint1"], [0.95]) == ()
