"""Fitted files know their robot (issue #15): calib.yaml records {name, dir, hash}; `stac` and
`predict` need no --robot for a robot outside robots/, and `predict` refuses, with one line, a
log of another robot or a robot whose files changed since the fit."""

import shutil
from dataclasses import replace

import pytest
import synth
import yaml
from typer.testing import CliRunner

from diegocal.cli import app
from diegocal.cli.testing import one_line_error
from diegocal.io import load_yaml, save_log
from diegocal.io.bundle import robot_hash
from diegocal.report.stac_pages import evaluate
from diegocal.stac.calibration import Calibration

runner = CliRunner()


def _run(*args):
    return runner.invoke(app, [str(a) for a in args])


@pytest.fixture(scope="module")
def fitted(tree_robot, tree_dir, tmp_path_factory):
    d = tmp_path_factory.mktemp("prov")
    log = synth.simulate(tree_robot, 300, seed=41)
    held = synth.simulate(tree_robot, 100, seed=42, truth=Calibration.from_dict(log.truth.params))
    save_log(replace(log, robot=str(tree_dir)), d / "train.h5")  # the log names its robot's directory
    save_log(replace(held, robot=None), d / "held.h5")  # an imported log: no robot named
    res = _run("stac", d / "train.h5", "--joint-angles", d / "train.q.h5", "-q")
    assert res.exit_code == 0, res.output
    return d, d / "train.calib.yaml"


def test_calib_records_its_robot(fitted, tree_dir, tree_robot):
    _, calib = fitted
    rec = load_yaml(calib)["robot"]
    assert rec == {"name": tree_robot.name, "dir": str(tree_dir.resolve()), "hash": robot_hash(tree_dir)}


def test_predict_and_report_need_no_robot(fitted, tmp_path):
    d, calib = fitted
    res = _run("predict", calib, d / "held.h5", "-o", tmp_path / "p.h5", "-q")
    assert res.exit_code == 0, res.output
    ev = evaluate(str(calib), None, (str(d / "held.h5"),))  # robot, fit log and held-out log found by the report
    assert not ev.note and ev.frames == 300 and ev.residuals
    assert len(ev.heldout) == 1 and ev.heldout_errors is not None and len(ev.heldout_errors)


def test_predict_refuses_a_changed_robot(fitted, tree_dir, tmp_path):
    d, calib = fitted
    other = tmp_path / "tree_edited"
    shutil.copytree(tree_dir, other)
    sensors = yaml.safe_load((other / "sensors.yaml").read_text())
    sensors["pots"][0]["gain"] *= 1.1
    (other / "sensors.yaml").write_text(yaml.safe_dump(sensors))
    log = synth.simulate(synth.load(other), 50, seed=43)
    save_log(replace(log, robot=str(other)), tmp_path / "other.h5")
    msg = one_line_error(_run("predict", calib, tmp_path / "other.h5"))
    assert "robot.urdf or sensors.yaml differ" in msg
    msg = one_line_error(_run("predict", calib, d / "held.h5", "--robot", other))
    assert "is not the robot" in msg and "differ" in msg


def test_predict_refuses_a_log_of_another_robot(fitted, tmp_path, tree_robot):
    d, calib = fitted
    log = synth.simulate(tree_robot, 50, seed=44)
    save_log(replace(log, robot="talos"), tmp_path / "talos.h5")
    msg = one_line_error(_run("predict", calib, tmp_path / "talos.h5"))
    assert "robot 'talos'" in msg
