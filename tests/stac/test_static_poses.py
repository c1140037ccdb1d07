"""Static-pose calibrations (issue #15): a UR5 (example-robot-data) held still in tens of poses,
encoders with gain 1, a rigid cluster of four markers on its tool, the mocap frame unknown. STAC
recovers the joint offsets against the simulator's truth and writes off the poses filed with
another pose's mocap frame (exactly those); `stac --cv` prints the leave-one-pose-out marker
error, close to the error the true calibration itself makes, with the wrong poses standing out."""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

sys.path.insert(0, str(Path(__file__).parents[1]))

import erd  # noqa: E402

from diegocal.cli import app  # noqa: E402
from diegocal.io import load_log, load_yaml, save_yaml  # noqa: E402
from diegocal.robot import load_robot  # noqa: E402
from diegocal.sim.static_poses import StaticPoseOptions, simulate_static_poses  # noqa: E402
from diegocal.stac import StacOptions, calibrate  # noqa: E402
from diegocal.stac.calibration import Calibration  # noqa: E402
from diegocal.stac.model import Observation  # noqa: E402
from diegocal.stac.predict import predict  # noqa: E402
from diegocal.stac.static import find_poses, take  # noqa: E402

JOINTS = ("shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint", "wrist_2_joint", "wrist_3_joint")
CLUSTER = [[0.05, 0.0, 0.02], [0.0, 0.05, 0.02], [-0.04, -0.03, 0.04], [0.0, 0.0, 0.08]]


@pytest.fixture(scope="module")
def ur5_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("ur5")
    shutil.copy(erd.urdf_path("ur5"), d / "robot.urdf")
    save_yaml(
        {
            "urdf": "robot.urdf",
            "base_link": "base_link",
            "pots": [{"name": j.replace("_joint", ""), "kind": "encoder", "joint": j} for j in JOINTS],
            "markers": [{"name": f"c{i}", "link": "tool0", "xyz": x} for i, x in enumerate(CLUSTER)],
        },
        d / "sensors.yaml",
    )
    return d


def _offsets(log, robot, cal):
    """Bias errors against the gauge-equivalent truth and their z-scores, on the biases a fit
    estimates (the gauge joints' are fixed: shoulder_pan by the mocap frame, wrist_3 by the cluster)."""
    truth = Calibration.from_dict(log.truth.params)
    obs = Observation(log.without_truth(), robot)
    obs.check_observable()
    free = ~obs.fixed_bias
    err = cal.bias - obs.gauge_equivalent_bias(truth.gain, truth.bias, cal.bias)
    return err[free], (err / cal.bias_se)[free]


def test_static_poses_recover_the_joint_offsets(ur5_dir):
    robot = load_robot(ur5_dir)
    log = simulate_static_poses(robot, StaticPoseOptions(n_poses=30), np.random.default_rng(1))
    assert len(np.unique(find_poses(log))) == 30
    cal = calibrate(log.without_truth(), robot).calibration
    assert {g["joint"] for g in cal.gauges} == {"shoulder_pan_joint", "wrist_3_joint"}
    err, z = _offsets(log, robot, cal)
    assert len(err) == 4 and np.all(np.abs(z) < 4.0) and np.abs(err).max() < 0.01  # rad


@pytest.mark.parametrize("wrong", [1, 3])
def test_poses_with_another_poses_markers_are_written_off(ur5_dir, wrong):
    robot = load_robot(ur5_dir)
    log = simulate_static_poses(robot, StaticPoseOptions(n_poses=30, wrong=wrong), np.random.default_rng(2))
    bad = log.truth.effects[0]["values"]["poses"]
    unchecked = calibrate(log.without_truth(), robot, StacOptions(check_poses=False)).calibration
    assert np.abs(_offsets(log, robot, unchecked)[0]).max() > 0.02  # one wrong pose is enough to spoil it
    # a robust loss's check of single frames finds them too (one sample per pose: frame k is pose k)
    frames = calibrate(log.without_truth(), robot, StacOptions(loss="huber", check_poses=False)).calibration
    assert list(frames.rejected) == bad
    for loss in ("linear", "tukey"):
        cal = calibrate(log.without_truth(), robot, StacOptions(loss=loss)).calibration
        assert [r["pose"] for r in cal.rejected_poses] == bad and not cal.rejected
        err, z = _offsets(log, robot, cal)
        assert np.all(np.abs(z) < 4.0) and np.abs(err).max() < 0.01, (loss, err, z)


def test_stac_cv_prints_the_leave_one_pose_out_error(ur5_dir, tmp_path):
    log_path = tmp_path / "poses.h5"
    res = CliRunner().invoke(
        app,
        [
            "simulate",
            "kinematics",
            "--robot",
            str(ur5_dir),
            "--poses",
            "12",
            "--wrong-poses",
            "1",
            "--seed",
            "3",
            "-o",
            str(log_path),
            "-q",
        ],
    )
    assert res.exit_code == 0, res.output
    res = CliRunner().invoke(app, ["stac", str(log_path), "--loss", "tukey", "--cv"])
    assert res.exit_code == 0, res.output
    assert "leave-one-pose-out marker error" in res.output and "poses > 5 x median error" in res.output
    cv = load_yaml(tmp_path / "poses.calib.yaml")["cv"]
    log = load_log(log_path)
    bad = log.truth.effects[0]["values"]["poses"]
    errors = np.array([p["marker_error"] for p in cv["poses"]])
    assert len(errors) == 12 and [p["pose"] for p in cv["poses"]] == list(range(12))
    assert np.flatnonzero(errors > 5 * np.median(errors)).tolist() == bad
    # the error the true calibration makes on each good pose, predicted from its own pots
    robot = load_robot(log.robot)
    truth = Calibration.from_dict(log.truth.params)
    poses = find_poses(log)
    own = [predict(take(log, np.flatnonzero(poses == k)), robot, truth).mae["markers"] for k in range(12)]
    good = np.setdiff1d(np.arange(12), bad)
    assert np.median(errors[good]) < 1.5 * np.median(np.array(own)[good])
