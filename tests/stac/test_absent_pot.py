"""A pot of sensors.yaml that the log lacks (issue #32 item 2: a misspelt channel) is listed as
unobservable, "no channel in the log", at its nominal values, and is not counted as calibrated;
the other pots are calibrated as before."""

from __future__ import annotations

import numpy as np
import pytest
import synth
from typer.testing import CliRunner

from diegocal.cli import app
from diegocal.io import Stream, load_yaml, save_log
from diegocal.stac import calibrate
from diegocal.stac.calibration import Calibration
from diegocal.stac.model import NO_CHANNEL


@pytest.fixture(scope="module")
def misspelt(tree_robot):
    """A tree session whose first rotary pot is logged under a misspelt name."""
    log = synth.simulate(tree_robot, 400, seed=41)
    pots = log.streams["pots"]
    name = next(p.name for p in tree_robot.sensors.pots if p.kind == "rotary")
    names = tuple(n + "x" if n == name else n for n in pots.names)
    return log.with_streams(pots=Stream(names, pots.data)), name


def test_a_pot_without_channel_is_unobservable_not_calibrated(tree_robot, misspelt):
    log, name = misspelt
    cal = calibrate(log.without_truth(), tree_robot).calibration
    absent = [u for u in cal.unobservable if u["pot"] == name]
    assert absent and absent[0]["reason"] == NO_CHANNEL == "no channel in the log"
    i = cal.pot_names.index(name)
    nominal = Calibration.nominal(tree_robot)
    assert cal.gain[i] == nominal.gain[i] and cal.bias[i] == nominal.bias[i]
    assert name not in cal.calibrated_pots and len(cal.calibrated_pots) == len(cal.pot_names) - 1
    truth = Calibration.from_dict(log.truth.params)
    others = [cal.pot_names.index(n) for n in cal.calibrated_pots]
    assert np.abs(cal.gain[others] / truth.gain[others] - 1).max() < 0.03
    written = cal.to_dict()["unobservable"]
    assert {"pot": name, "joints": list(tree_robot.sensors.pots[i].joints), "reason": NO_CHANNEL} in written
    assert Calibration.from_dict(cal.to_dict()).calibrated_pots == cal.calibrated_pots


def test_stac_lists_the_absent_pot_in_calib_yaml(tree_dir, misspelt, tmp_path):
    log, name = misspelt
    save_log(log, tmp_path / "run.h5")
    res = CliRunner().invoke(app, ["stac", str(tmp_path / "run.h5"), "--robot", str(tree_dir), "-q"])
    assert res.exit_code == 0, res.output
    listed = load_yaml(tmp_path / "run.calib.yaml")["unobservable"]
    assert [u["reason"] for u in listed if u["pot"] == name] == [NO_CHANNEL]
