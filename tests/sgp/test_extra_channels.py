"""Joint channels the robot model does not move (issue #32 item 5): a gripper's motor beside an
arm's joints is left out of `sgp-fit` with one warning naming it, not fatal; a joint the model
holds still is said to be locked, at what and why, not "not a joint of the robot"."""

from __future__ import annotations

import logging

import numpy as np
import pytest
from typer.testing import CliRunner

from diegocal.cli import app
from diegocal.io import Log, make_stream, save_log
from diegocal.robot import load_robot
from diegocal.sgp import SGPOptions, fit_dynamics
from diegocal.sgp.streams import log_arrays
from tests.sgp.conftest import ARM2_URDF, SENSORS, write_robot


def with_channel(log: Log, name: str, rng) -> Log:
    """The log with one more channel ``name`` in every joint stream (a motor the URDF lacks)."""
    extra = rng.normal(size=log.n_samples)
    streams = dict(log.streams)
    for s in ("q", "qd", "qdd", "tau"):
        old = log.streams[s]
        streams[s] = make_stream(old.names + (name,), np.column_stack([old.data, extra]))
    return Log(log.time, streams, robot=log.robot)


@pytest.fixture(scope="module")
def arm_log(arm2, simulate):
    return simulate(arm2, T=200, seed=3)[0]


def test_a_gripper_channel_is_left_out_with_one_warning(arm2, arm_log, caplog):
    log = with_channel(arm_log, "gripper_motor", np.random.default_rng(0))
    with caplog.at_level(logging.WARNING):
        model = fit_dynamics(log, arm2, SGPOptions(kind="pr"))
    lines = [r.getMessage() for r in caplog.records if "gripper_motor" in r.getMessage()]
    assert len(lines) == 1 and "gripper_motor (q, qd, qdd, tau)" in lines[0], lines
    assert "not joints of robot 'arm2'" in lines[0]
    assert model.joint_names == ("shoulder", "elbow")
    plain = fit_dynamics(arm_log, arm2, SGPOptions(kind="pr"))
    np.testing.assert_allclose(model.parametric_.values, plain.parametric_.values)


def test_sgp_fit_ignores_the_gripper(arm2_dir, arm_log, tmp_path):
    save_log(with_channel(arm_log, "gripper_motor", np.random.default_rng(1)), tmp_path / "run.h5")
    res = CliRunner().invoke(app, ["sgp-fit", str(tmp_path / "run.h5"), "--robot", str(arm2_dir), "-m", "pr", "-q"])
    assert res.exit_code == 0, res.output
    assert "gripper_motor" in res.output and (tmp_path / "run.sgp").is_dir()


def test_a_locked_joint_is_said_to_be_locked(tmp_path, arm_log, caplog):
    robot = load_robot(write_robot(tmp_path / "arm2", ARM2_URDF), joints=("shoulder", "elbow"))
    (tmp_path / "arm2" / "sensors.yaml").write_text(SENSORS + "locked: {elbow: 0.3}\n")
    locked = load_robot(tmp_path / "arm2", joints=("shoulder", "elbow"))
    assert robot.joint_names == ("shoulder", "elbow") and locked.joint_names == ("shoulder",)
    with caplog.at_level(logging.WARNING):
        q, _, _, tau = log_arrays(arm_log, locked)
    assert q.shape == (arm_log.n_samples, 1) and tau.shape == q.shape
    text = caplog.text
    assert "elbow (q, qd, qdd, tau): a joint the model holds still at 0.3 (sensors.yaml locks it)" in text
    assert "its motion is not modelled" in text


def test_a_torque_stream_of_other_devices_only_is_one_error(arm2, arm_log):
    from diegocal.errors import MissingStreamError

    streams = dict(arm_log.streams, tau=make_stream(["gripper_motor"], arm_log.stream("tau").data[:, :1]))
    with pytest.raises(MissingStreamError, match="no channel of robot 'arm2'.*gripper_motor"):
        fit_dynamics(Log(arm_log.time, streams, robot=arm_log.robot), arm2, SGPOptions(kind="pr"))
