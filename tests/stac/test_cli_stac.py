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
    res = _run(
        "stac", d / "train.h5", "--robot", tree_dir, "--max-iterations", 20, "--joint-angles", d / "q.h5", "--quiet"
    )
    assert res.exit_code == 0, res.output
    return d / "train.calib.yaml"


def test_stac_writes_calib_and_q(fitted, logs, tree_robot):
    d, log = logs
    data = load_yaml(fitted)
    assert {"pots", "markers", "mocap", "sigma", "fit", "meta"} <= set(data)
    assert len(data["fit"]["history"]) == data["fit"]["iterations"]
    assert data["meta"]["log"].endswith("train.h5")
    cal = Calibration.from_dict(data)
    truth = Calibration.from_dict(log.truth.params)
    assert np.abs(cal.gain / truth.gain - 1).max() < 0.03
    assert data["meta"]["joint_angles"].endswith("q.h5") and not (d / "train.q.h5").exists()
    q = load_log(d / "q.h5").streams["q"]
    assert q.names == tree_robot.joint_names and q.data.shape == (400, tree_robot.n_joints)


def test_predict_and_report(fitted, logs, tree_dir, tmp_path):
    d, _ = logs
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
    pred = load_log(tmp_path / "pred.h5")
    assert {"q", "pots", "markers"} <= set(pred.streams)
    rows = load_yaml(fitted)["prediction"]
    assert rows[-1]["from"] == ["linear", "rotary"] and rows[-1]["mae"]["markers"] < 0.01
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


def test_unknown_pot_and_marker_names(logs, tree_dir, tmp_path):
    _, log = logs
    p = log.streams["pots"]
    renamed = synth.make_stream(("bogus",) + p.names[1:], p.data)
    assert "'bogus' is not in" in _bad(tmp_path, log.with_streams(pots=renamed).without_truth(), tree_dir)
    m = log.streams["markers"]
    renamed = synth.make_stream(m.names[:-1] + ("m_ghost",), m.data)
    assert "'m_ghost' is not in" in _bad(tmp_path, log.with_streams(markers=renamed).without_truth(), tree_dir)


def test_markers_all_on_base_are_unobservable(tmp_path):
    rdir = synth.make_tree_robot(tmp_path / "base_robot", synth.SMALL_CHAINS, seed=1, markers_on_base=True)
    log = synth.simulate(synth.load(rdir), 50, seed=1)
    out = _bad(tmp_path, log, rdir)
    assert "unobservable" in out


def test_unknown_method_and_loss(logs, tree_dir, tmp_path):
    _, log = logs
    assert "unknown method" in _bad(tmp_path, log, tree_dir, "--method", "magic")
    assert "unknown loss" in _bad(tmp_path, log, tree_dir, "--loss", "cauchy")


def test_predict_unknown_sensor_type(fitted, logs, tree_dir):
    d, _ = logs
    res = _run("predict", fitted, d / "held.h5", "--robot", tree_dir, "--from", "tendon")
    assert res.exit_code != 0 and "no sensors of that type" in res.output
