"""The README's "bring your own robot" example (docs/example_robot: a URDF and a sensors.yaml
written by hand, not by scripts/) calibrated and identified from the command line, against the
simulator's truth, with held-out data cut as a contiguous block by `diegocal split`."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from diegocal.cli import app
from diegocal.io import load_log, load_yaml
from diegocal.robot import gauge_joints, load_robot
from diegocal.stac.calibration import Calibration

ROBOT = Path(__file__).resolve().parents[1] / "docs" / "example_robot"
runner = CliRunner()


def _run(*args):
    res = runner.invoke(app, [str(a) for a in args])
    assert res.exit_code == 0, res.output
    return res


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory):
    d = tmp_path_factory.mktemp("example")
    _run("simulate", "kinematics", "--robot", ROBOT, "-o", d / "run.h5", "--duration", 20, "--seed", 3)
    _run("split", d / "run.h5", "--at", 0.8, "-o", d / "train.h5", d / "held.h5")
    _run("stac", d / "train.h5", "-q")
    return d


def test_a_linear_pot_across_the_elbow_fixes_its_zero():
    # the markers on the forearm alone would absorb an elbow offset (a leaf gauge); the rod's
    # anchor distance changes non-uniformly with it, so its zero is determined
    assert gauge_joints(load_robot(ROBOT)) == ("shoulder",)


def test_pots_calibrated_to_truth(calibrated):
    d = calibrated
    truth = Calibration.from_dict(load_log(d / "run.h5").truth.params)
    raw = load_yaml(d / "train.calib.yaml")
    cal = Calibration.from_dict(raw)
    assert [g["joint"] for g in raw["gauges"]] == ["shoulder"]  # the mocap frame absorbs its zero
    for i, name in enumerate(cal.pot_names):
        t = truth.pot_names.index(name)
        assert abs(cal.gain[i] / truth.gain[t] - 1) < 0.01, name
        if np.isfinite(cal.bias_se[i]):  # the elbow's two pots: estimated, within 4 standard errors
            assert abs(cal.bias[i] - truth.bias[t]) < 4 * cal.bias_se[i], name
    assert cal.fit.converged


def test_held_out_markers_predicted_from_the_pots(calibrated, tmp_path):
    d = calibrated
    _run("predict", d / "train.calib.yaml", d / "held.h5", "--from", "pots", "--to", "markers", "-o", tmp_path / "p.h5")
    pred, held = load_log(tmp_path / "p.h5"), load_log(d / "held.h5")
    err = np.linalg.norm(pred.streams["markers"].data - held.streams["markers"].data, axis=-1)
    assert np.nanmean(err) < 0.006  # m: a few marker noise levels (2 mm per axis)
