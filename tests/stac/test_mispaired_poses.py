"""Static poses filed with another pose's markers (issue #32 item 9: the mocap clock drifted) are
found by their disagreement with the rest, written off and listed, whatever the loss; the
calibration then equals the one from the clean session within its standard errors.

Robots of example-robot-data with a rotary pot on every joint and three markers on every moving
link (tests/erd.py); 34 poses, the markers of 8 consecutive ones taken from the pose three later.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

sys.path.insert(0, str(Path(__file__).parents[1]))

import erd  # noqa: E402

from diegocal.cli import app  # noqa: E402
from diegocal.io import Stream, load_yaml, save_log  # noqa: E402
from diegocal.robot import load_robot  # noqa: E402
from diegocal.sim.static_poses import StaticPoseOptions, simulate_static_poses  # noqa: E402
from diegocal.stac import calibrate  # noqa: E402
from diegocal.stac.calibration import REJECTED_POSES_REASON, Calibration  # noqa: E402

N_POSES, WRONG, SHIFT = 34, np.arange(10, 18), 3


def mispaired(log, samples: int):
    """The log with the marker rows of the poses WRONG taken from the pose SHIFT later."""
    x = log.streams["markers"].data.copy()
    src = x.copy()
    for k in WRONG:
        j = (k + SHIFT) % N_POSES
        x[k * samples : (k + 1) * samples] = src[j * samples : (j + 1) * samples]
    return log.with_streams(markers=Stream(log.streams["markers"].names, x))


@pytest.mark.parametrize(("name", "samples", "seed"), [("ur5", 1, 12), ("panda", 3, 11)])
def test_mispaired_poses_are_written_off(tmp_path, name, samples, seed):
    robot = load_robot(erd.robot_dir(tmp_path, name, marker_every=1))
    log = simulate_static_poses(robot, StaticPoseOptions(n_poses=N_POSES, samples=samples), np.random.default_rng(seed))
    clean = calibrate(log.without_truth(), robot).calibration
    assert clean.rejected_poses == ()
    cal = calibrate(mispaired(log, samples).without_truth(), robot).calibration
    assert [r["pose"] for r in cal.rejected_poses] == WRONG.tolist()
    assert [r["frame"] for r in cal.rejected_poses] == (WRONG * samples).tolist()
    assert all(r["samples"] == samples and r["disagreement"] > 1 for r in cal.rejected_poses)
    assert cal.fit.converged and not cal.rejected
    for fitted, reference, se in (
        (cal.gain, clean.gain, clean.gain_se),
        (cal.bias, clean.bias, clean.bias_se),
        (cal.marker_xyz, clean.marker_xyz, clean.marker_xyz_se),
    ):
        z = (fitted - reference) / se
        assert np.all(np.abs(z[np.isfinite(z)]) < 3.0), np.round(z, 2)
    written = cal.to_dict()["rejected_poses"]
    assert written["reason"] == REJECTED_POSES_REASON and len(written["poses"]) == len(WRONG)
    assert Calibration.from_dict(cal.to_dict()).rejected_poses == cal.rejected_poses


def test_stac_writes_the_rejected_poses_in_calib_yaml(tmp_path):
    robot_dir = erd.robot_dir(tmp_path, "ur5", marker_every=1)
    robot = load_robot(robot_dir)
    log = simulate_static_poses(robot, StaticPoseOptions(n_poses=N_POSES), np.random.default_rng(12))
    save_log(mispaired(log, 1), tmp_path / "poses.h5")
    res = CliRunner().invoke(app, ["stac", str(tmp_path / "poses.h5"), "--robot", str(robot_dir), "-q"])
    assert res.exit_code == 0, res.output
    written = load_yaml(tmp_path / "poses.calib.yaml")["rejected_poses"]
    assert [p["pose"] for p in written["poses"]] == WRONG.tolist()
