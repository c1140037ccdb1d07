"""A torque that a sensor's range or a drive's current limit clipped: the samples at the limit are
left out of fits and scores with one warning, so that no cause stands in for the clipping (a user
trial's Z1 shoulder, clipped in a fifth of its samples, got a torque offset and a position friction)."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from diegocal.diagnose import DiagnoseOptions, diagnose
from diegocal.io import Log, make_stream
from diegocal.predict import predict
from diegocal.robot.resolve import robot_for_log
from diegocal.sgp import SGPOptions
from diegocal.sgp.model import fit_dynamics
from diegocal.sgp.store import save_model
from diegocal.sgp.streams import clipped_samples, torque_array
from experiments.dynamics_generator import Session, generate, urdf


def test_the_samples_at_a_limit_are_found_and_a_quantised_peak_is_not():
    rng = np.random.default_rng(0)
    t = np.linspace(0.0, 40.0, 8000)
    x = np.sin(2 * np.pi * 0.3 * t) + 0.3 * np.sin(2 * np.pi * 0.71 * t) + 0.01 * rng.standard_normal(t.size)
    assert not clipped_samples(x).any()
    for quantum in (1e-3, 1e-2, 5e-2):  # a torque logged in steps: its peaks spread over the top levels
        assert not clipped_samples(np.round(x / quantum) * quantum).any(), quantum
        assert not clipped_samples(np.round(np.sin(2 * np.pi * 0.3 * t) / quantum) * quantum).any(), quantum
    clipped = np.clip(x, -1.0, 0.9)
    np.testing.assert_array_equal(clipped_samples(clipped), (x < -1.0) | (x > 0.9))


@pytest.mark.skipif(not urdf("ur5").is_file(), reason="example-robot-data is not installed")
def test_a_clipped_joint_is_left_out_with_a_warning_and_nothing_is_named(caplog):
    """The independent generator's UR5 with its shoulder's torque clipped at 80 % of its peak: named
    a position friction before the clipped samples were left out."""
    log = generate(Session(duration=20.0, seed=1, robot_seed=1, smooth_scale=0.0))
    robot = robot_for_log(None, log)
    tau = log.stream("tau")
    data = tau.data.copy()
    limit = 0.8 * np.abs(data[:, 1]).max()
    data[:, 1] = np.clip(data[:, 1], -limit, limit)
    streams = {k: log.stream(k) for k in ("q", "qd", "qdd")} | {"tau": make_stream(tau.names, data)}
    clipped = Log(time=log.time, streams=streams, robot=log.robot, rate_hz=log.rate_hz)
    with caplog.at_level(logging.WARNING, logger="diegocal"):
        got, joints = torque_array(clipped, robot)
    (record,) = caplog.records
    assert f"tau of {joints[1]} reads exactly" in record.getMessage() and "left out" in record.getMessage()
    assert np.isnan(got[:, 1]).sum() == int((np.abs(data[:, 1]) >= limit).sum()) > 0
    assert np.isfinite(np.delete(got, 1, axis=1)).all()
    d = diagnose(clipped, robot, DiagnoseOptions(domain="dynamics"))
    assert not d.findings, [f.term.label for f in d.findings]


@pytest.mark.skipif(not urdf("ur5").is_file(), reason="example-robot-data is not installed")
def test_predict_scores_a_clipped_joint_on_its_other_samples(tmp_path):
    log = generate(Session(duration=10.0, seed=2, robot_seed=2, smooth_scale=0.0))
    robot = robot_for_log(None, log)
    model = fit_dynamics(log, robot, SGPOptions(kind="pr"))
    save_model(model, tmp_path / "pr.sgp")
    tau = log.stream("tau")
    data = tau.data.copy()
    limit = 0.8 * np.abs(data[:, 1]).max()
    data[:, 1] = np.clip(data[:, 1], -limit, limit)
    streams = {k: log.stream(k) for k in ("q", "qd", "qdd")} | {"tau": make_stream(tau.names, data)}
    p = predict(tmp_path / "pr.sgp", Log(time=log.time, streams=streams, robot=log.robot, rate_hz=log.rate_hz))
    rows = dict(p.rows)
    kept = np.abs(data[:, 1]) < limit
    e = p.log.stream("tau").data[kept, 1] - data[kept, 1]
    assert rows[f"RMSE {tau.names[1]}"] == pytest.approx(np.sqrt(np.mean(e * e)), rel=1e-9)
    np.testing.assert_array_equal(p.log.stream("tau_measured").data[:, 1], data[:, 1])  # the log as it was
