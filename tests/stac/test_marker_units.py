"""Markers in mm where the log wants m (user trial: `stac` converged with σ markers 32 m and markers
65 m from their links): where the markers meet the robot (:class:`~diegocal.stac.model.Observation`)
a spread far beyond what the robot can span is one error line, for every command that binds markers
to a robot; legitimate logs (bundled sample data, a mocap frame far from the base, ghost markers)
pass."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import synth
from typer.testing import CliRunner

from diegocal.cli import app
from diegocal.cli.testing import one_line_error
from diegocal.errors import LogFormatError
from diegocal.io import Stream, load_log, save_log
from diegocal.robot.resolve import robot_for_log
from diegocal.stac.model import Observation
from diegocal.stac.scale import POT_FACTOR, SPAN_FACTOR, marker_span, marker_spread, pot_range

SAMPLE = Path(__file__).resolve().parents[2] / "sample_data"
HINT = "markers in mm? the log wants m (convert them, or import with the mocap file's unit)"
runner = CliRunner()


def _scaled(log, factor: float = 1.0, shift=(0.0, 0.0, 0.0)):
    m = log.streams["markers"]
    return log.with_streams(markers=Stream(m.names, m.data * factor + np.asarray(shift)))


@pytest.fixture(scope="module")
def session(tree_robot):
    return synth.simulate(tree_robot, 200, seed=51)


@pytest.fixture(scope="module")
def mm_log(session, tmp_path_factory):
    path = tmp_path_factory.mktemp("mm") / "mm.h5"
    save_log(_scaled(session, 1000.0), path)
    return path


def test_markers_in_mm_are_one_error_line(tree_dir, mm_log):
    out = mm_log.with_name("out.calib.yaml")
    line = one_line_error(runner.invoke(app, ["stac", str(mm_log), "--robot", str(tree_dir), "-o", str(out), "-q"]))
    assert HINT in line and "the log's markers spread" in line and "m at most" in line
    assert not out.exists()


@pytest.mark.parametrize("method", ["classical", "ekf"])
def test_the_other_methods_refuse_markers_in_mm(tree_dir, mm_log, method):
    out = mm_log.with_name(f"{method}.calib.yaml")
    args = ["stac", str(mm_log), "--robot", str(tree_dir), "--method", method, "-o", str(out), "-q"]
    assert HINT in one_line_error(runner.invoke(app, args)) and not out.exists()


def test_predict_and_diagnose_refuse_markers_in_mm(tree_dir, session, mm_log, tmp_path):
    good = tmp_path / "good.h5"
    save_log(session, good)
    cal = tmp_path / "nominal.calib.yaml"
    res = runner.invoke(app, ["stac", str(good), "--robot", str(tree_dir), "--method", "nominal", "-o", str(cal), "-q"])
    assert res.exit_code == 0, res.output
    pred = tmp_path / "pred.h5"
    res = runner.invoke(app, ["predict", str(cal), str(mm_log), "--robot", str(tree_dir), "-o", str(pred), "-q"])
    assert res.exit_code == 1 and HINT in one_line_error(res) and not pred.exists()
    diag = tmp_path / "mm.diagnosis.yaml"
    args = ["diagnose", str(mm_log), "--domain", "kinematics", "--robot", str(tree_dir), "-o", str(diag)]
    res = runner.invoke(app, args)
    assert res.exit_code == 1 and HINT in res.output.strip().splitlines()[-1] and "Traceback" not in res.output
    assert not diag.exists() and not list(tmp_path.glob("*extended*"))


def test_a_far_mocap_frame_and_ghost_markers_pass(tree_robot, session):
    far = _scaled(session, shift=(120.0, -80.0, 35.0))  # spreads, not positions
    Observation(far, tree_robot)
    m = far.streams["markers"].data.copy()
    rng = np.random.default_rng(52)
    ghosts = rng.random(m.shape[:2]) < 0.03  # 3 % of the readings 40 m off: a ghost marker each
    m[ghosts] += 40.0
    Observation(far.with_streams(markers=Stream(far.streams["markers"].names, m)), tree_robot)
    with pytest.raises(LogFormatError, match="markers in mm"):
        Observation(_scaled(session, 1000.0), tree_robot)


@pytest.mark.parametrize(
    "name", ["diego_kinematics.h5", "diego_kinematics_heldout.h5", "finger_hidden_nonlinearity.h5"]
)
def test_bundled_sample_data_is_far_inside_the_bound(name):
    log = load_log(SAMPLE / name)
    robot = robot_for_log(None, log)
    obs = Observation(log, robot)  # no error
    spread, span = marker_spread(obs.markers), marker_span(robot, obs.marker_specs)
    assert spread < span < SPAN_FACTOR * span  # a bound on the distance between two markers
    assert 1000 * spread > 10 * SPAN_FACTOR * span  # the same log in mm is far past it
    reach = pot_range(robot, obs.pot_specs, obs.A)  # the pots: what their gains allow
    ok = np.isfinite(reach)
    lo, hi = np.percentile(obs.pots[:, ok], [1, 99], axis=0)
    ratio = np.median((hi - lo) / reach[ok])
    assert ratio < 2.0 < POT_FACTOR < 1000 * ratio  # the same pots in mV are far past the bound


def _pots_scaled(log, factor: float):
    p = log.streams["pots"]
    return log.with_streams(pots=Stream(p.names, p.data * factor))


def test_pots_in_millivolts_are_one_error_line(tree_dir, session, tmp_path):
    # a user trial: pots in mV against gains in V/rad 'converged' to gains 400 times the truth
    path = tmp_path / "mv.h5"
    save_log(_pots_scaled(session, 1000.0), path)
    out = tmp_path / "out.calib.yaml"
    line = one_line_error(runner.invoke(app, ["stac", str(path), "--robot", str(tree_dir), "-o", str(out), "-q"]))
    assert "the log's pots vary" in line and "(mV against V/rad?)" in line
    assert not out.exists()


TURN_URDF = """<?xml version="1.0"?>
<robot name="turn">
  <link name="base"/>
  <link name="table"><inertial><mass value="1.0"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/>
  </inertial></link>
  <link name="arm"><inertial><mass value="1.0"/><origin xyz="0.1 0 0"/>
  <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial></link>
  <joint name="spin" type="continuous"><parent link="base"/><child link="table"/><origin xyz="0 0 0.1"/>
  <axis xyz="0 0 1"/></joint>
  <joint name="lift" type="revolute"><parent link="table"/><child link="arm"/><origin xyz="0.1 0 0"/>
  <axis xyz="0 1 0"/><limit lower="-1" upper="1" effort="10" velocity="3"/></joint>
</robot>
"""
TURN_SENSORS = """urdf: robot.urdf
base_link: base
pots:
  - {name: spin, kind: encoder, joint: spin}
markers:
  - {name: m1, link: arm, xyz: [0.2, 0, 0]}
"""


def test_a_multi_turn_encoder_on_a_continuous_joint_is_not_taken_for_millivolts(tmp_path):
    # a review: a continuous joint's ±π were taken as limits, and 40 turns as pots in mV
    from diegocal.io import Log, make_stream
    from diegocal.robot import load_robot

    (tmp_path / "robot.urdf").write_text(TURN_URDF)
    (tmp_path / "sensors.yaml").write_text(TURN_SENSORS)
    robot = load_robot(tmp_path)
    t = np.arange(500) * 0.02
    turns = (t * 2 * np.pi * 4.0)[:, None]  # 40 turns in 10 s
    log = Log(t, {"pots": make_stream(["spin"], turns), "markers": make_stream(["m1"], np.full((500, 1, 3), 0.1))})
    Observation(log, robot)  # no error
