"""`diegocal stac`, `diegocal predict calib.yaml` and the report section, end to end; bad input
gives one clear line and a non-zero exit."""

import numpy as np
import pytest
import synth
from typer.testing import CliRunner

from diegocal.cli import app
from diegocal.io import Log, load_log, load_yaml, save_log
from diegocal.stac.calibration import Calibration

runner = CliRunner()


@pytest.fixture(scope="module")
def logs(tree_robot, tmp_path_factory):
    d = tmp_path_factory.mktemp("logs")
    log = synth.simulate(tree_robot, 400, seed=31)
    held = synth.simulate(tree_robot, 200, seed=32, truth=Calibration.from_dict(log.truth.params))
    save_log(log, d / "train.h5")
    save_log(held, d / "held.h5")
    return d, log


def _run(*args):
    return runner.invoke(app, [str(a) for a in args])


@pytest.fixture(scope="module")
def fitted(logs, tree_dir):
    d, _ = logs
    res = _run("stac", d / "train.h5", "--robot", tree_dir, "--joint-angles", d / "q.h5")
    assert res.exit_code == 0, res.output
    assert "−log-likelihood, eq. 2.5 (nats" in " ".join(res.output.split())  # the cost says what it is
    return d / "train.calib.yaml"


def test_stac_writes_calib_and_q(fitted, logs, tree_robot):
    d, log = logs
    data = load_yaml(fitted)
    assert {"layout", "baseline", "sigma", "fit", "kind", "robot", "log", "command", "version"} <= set(data)
    assert len(data["fit"]["history"]) == data["fit"]["iterations"]
    assert data["kind"] == "kinematics" and data["log"].endswith("train.h5")
    assert data["robot"]["name"] == tree_robot.name and data["robot"]["hash"].startswith("sha256:")
    cal = Calibration.from_dict(data)
    truth = Calibration.from_dict(log.truth.params)
    assert np.abs(cal.gain / truth.gain - 1).max() < 0.03
    assert data["meta"]["joint_angles"].endswith("q.h5") and not (d / "train.q.h5").exists()
    q = load_log(d / "q.h5").streams["q"]
    assert q.names == tree_robot.joint_names and q.data.shape == (400, tree_robot.n_joints)


def test_predict_and_report(fitted, logs, tree_dir, tmp_path):
    d, _ = logs
    before = fitted.read_bytes()
    res = _run(
        "predict",
        fitted,
        d / "held.h5",
        "--robot",
        tree_dir,
        "--from",
        "pots",
        "--to",
        "markers,rotary",
        "-o",
        tmp_path / "pred.h5",
    )
    assert res.exit_code == 0, res.output
    assert "MAE" in res.output and "markers" in res.output
    assert "MAE from pots (" in " ".join(res.output.split())  # as asked, then the pot kinds it stands for
    pred = load_log(tmp_path / "pred.h5")
    assert {"q", "pots", "markers"} <= set(pred.streams)
    assert fitted.read_bytes() == before  # predict never writes into the model it reads
    assert "warning" not in res.output  # the same session's held-out data: a plausible error
    res = _run("report", fitted, "-o", tmp_path / "r.pdf", "--robot", tree_dir, "--quiet")
    assert res.exit_code == 0, res.output
    assert (tmp_path / "r.pdf").stat().st_size > 10_000


def test_nominal_method(logs, tree_dir, tmp_path):
    d, _ = logs
    res = _run(
        "stac",
        d / "train.h5",
        "--robot",
        tree_dir,
        "--method",
        "nominal",
        "-o",
        tmp_path / "n.yaml",
    )
    assert res.exit_code == 0, res.output
    assert load_yaml(tmp_path / "n.yaml")["method"] == "nominal"


def _bad(tmp_path, log: Log, tree_dir, *extra):
    save_log(log, tmp_path / "bad.h5")
    res = _run("stac", tmp_path / "bad.h5", "--robot", tree_dir, "--quiet", *extra)
    assert res.exit_code != 0
    assert "Traceback" not in res.output
    return res.output


def test_log_without_markers(logs, tree_dir, tmp_path):
    _, log = logs
    out = _bad(tmp_path, Log(log.time, {"pots": log.streams["pots"]}, robot=log.robot), tree_dir)
    assert "no 'markers' stream" in out


def test_log_without_pots(logs, tree_dir, tmp_path):
    _, log = logs
    out = _bad(tmp_path, Log(log.time, {"markers": log.streams["markers"]}, robot=log.robot), tree_dir)
    assert "no 'pots' stream" in out


def test_a_log_whose_markers_the_robot_does_not_name_asks_whether_the_robot_is_right(logs, tree_dir, tmp_path):
    """A user trial ran stac with another robot's --robot: "the markers stream has no channels"
    while the log had nine; the error now says none is the robot's and points at --robot."""
    _, log = logs
    m = log.streams["markers"]
    other = synth.make_stream(tuple(f"other_{n}" for n in m.names), m.data)
    out = _bad(tmp_path, log.with_streams(markers=other).without_truth(), tree_dir)
    assert "no marker of the robot's sensors.yaml has a channel in the log" in out and "--robot" in out
    assert not (tmp_path / "bad.calib.yaml").exists()


def test_unknown_pot_and_marker_names_are_ignored_with_one_line(logs, tree_dir, tmp_path):
    """Log channels sensors.yaml does not name are left out, with one warning line naming them
    (and the close match of a typo)."""
    _, log = logs
    p, m = log.streams["pots"], log.streams["markers"]
    pots = synth.make_stream(p.names + ("bogus",), np.column_stack([p.data, p.data[:, 0]]))
    markers = synth.make_stream(m.names + (m.names[0] + "x",), np.concatenate([m.data, m.data[:, :1]], axis=1))
    save_log(log.with_streams(pots=pots, markers=markers).without_truth(), tmp_path / "extra.h5")
    res = _run("stac", tmp_path / "extra.h5", "--robot", tree_dir, "--quiet")
    assert res.exit_code == 0, res.output
    warnings = [line for line in res.output.splitlines() if line.startswith("warning:")]
    assert len(warnings) == 1, res.output
    assert "1 log pots (bogus)" in warnings[0] and f"did you mean '{m.names[0]}'" in warnings[0]
    assert "bogus" not in Calibration.from_dict(load_yaml(tmp_path / "extra.calib.yaml")).pot_names


def test_markers_all_on_base_are_unobservable(tmp_path):
    rdir = synth.make_tree_robot(tmp_path / "base_robot", synth.SMALL_CHAINS, seed=1, markers_on_base=True)
    log = synth.simulate(synth.load(rdir), 50, seed=1)
    out = _bad(tmp_path, log, rdir)
    assert "unobservable" in out


def test_unknown_method_and_loss(logs, tree_dir, tmp_path):
    _, log = logs
    assert "'--method': 'magic' is not one of" in _bad(tmp_path, log, tree_dir, "--method", "magic")
    assert "'--loss': 'cauchy' is not one of" in _bad(tmp_path, log, tree_dir, "--loss", "cauchy")


def test_predict_unknown_sensor_type(fitted, logs, tree_dir):
    d, _ = logs
    res = _run("predict", fitted, d / "held.h5", "--robot", tree_dir, "--from", "tendon")
    assert res.exit_code != 0 and "no sensors of that type" in res.output
