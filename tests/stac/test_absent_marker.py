"""A marker of sensors.yaml that the log lacks (renamed in the file, user trial) keeps its nominal
position with a null standard error, as an absent pot keeps its gain and bias: it gets the same kind
of warning line, and the stac summary counts the markers the log has ("11 of 12 seen")."""

from __future__ import annotations

import numpy as np
import pytest
import synth
from typer.testing import CliRunner

from diegocal.cli import app
from diegocal.io import Stream, load_yaml, save_log
from diegocal.stac.calibration import Calibration
from diegocal.stac.model import NO_CHANNEL

runner = CliRunner()


@pytest.fixture(scope="module")
def renamed(tree_robot):
    """A tree session whose first marker is logged under another name."""
    log = synth.simulate(tree_robot, 400, seed=61)
    m = log.streams["markers"]
    name = m.names[0]
    names = tuple(name + "_b" if n == name else n for n in m.names)
    return log.with_streams(markers=Stream(names, m.data)), name


def test_stac_warns_of_the_absent_marker_and_counts_the_seen_ones(tree_dir, tree_robot, renamed, tmp_path):
    log, name = renamed
    save_log(log, tmp_path / "run.h5")
    res = runner.invoke(app, ["stac", str(tmp_path / "run.h5"), "--robot", str(tree_dir)])
    assert res.exit_code == 0, res.output
    text = " ".join(res.output.split())
    total = len(tree_robot.sensors.markers)
    assert f"markers │ {total - 1} of {total} seen" in text
    warning = next(line for line in res.output.splitlines() if "not calibrated" in line)
    assert f"1 marker(s) of {tree_robot.name}'s sensors.yaml not calibrated: {name}" in warning
    assert f"did you mean {name + '_b'!r}?" in warning and f"({NO_CHANNEL})" in warning
    assert "keep their nominal values (standard error null)" in warning
    cal = Calibration.from_dict(load_yaml(tmp_path / "run.calib.yaml"))
    i = cal.marker_names.index(name)
    assert np.isnan(cal.marker_xyz_se[i]).all()
    assert np.array_equal(cal.marker_xyz[i], Calibration.nominal(tree_robot).marker_xyz[i])


def test_a_log_with_every_marker_says_all_seen_and_warns_of_none(tree_dir, tree_robot, tmp_path):
    save_log(synth.simulate(tree_robot, 200, seed=62), tmp_path / "run.h5")
    res = runner.invoke(app, ["stac", str(tmp_path / "run.h5"), "--robot", str(tree_dir)])
    assert res.exit_code == 0, res.output
    total = len(tree_robot.sensors.markers)
    assert f"markers │ {total} of {total} seen" in " ".join(res.output.split())
    assert "not calibrated" not in res.output


def test_predict_says_an_absent_marker_is_not_scored_not_that_it_is_nominal(tree_robot):
    """A review: `predict` on a log with a marker renamed warned that it "keeps its nominal values";
    a prediction keeps the calibration's positions and does not score that marker."""
    from diegocal.stac.model import absent_line

    line = absent_line(("m2",), ("m2_x", "m1"), tree_robot, "predict")
    assert "not in this log: m2" in line and "not scored" in line and "nominal" not in line
    assert "keep their nominal values" in absent_line(("m2",), ("m1",), tree_robot)
