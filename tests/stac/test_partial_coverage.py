"""Partial sensor coverage is normal (issue #15): iCub from example-robot-data with a pot on each of
its 32 joints and one marker on every other link. STAC calibrates what the data determine, keeps
the rest at nominal and says so (calib.yaml ``unobservable``/``gauges``, one warning, the summary
and the report), checked against the simulator's truth."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

sys.path.insert(0, str(Path(__file__).parents[1]))

import erd  # noqa: E402

from diegocal.cli import app  # noqa: E402
from diegocal.io import load_log, load_yaml  # noqa: E402
from diegocal.report.registry import ReportContext  # noqa: E402
from diegocal.report.stac_pages import abstract, marker_table, pot_table  # noqa: E402
from diegocal.robot import load_robot  # noqa: E402
from diegocal.robot.gauges import gauge_axes  # noqa: E402
from diegocal.stac.calibration import Calibration  # noqa: E402
from diegocal.stac.model import Observation  # noqa: E402

runner = CliRunner()


@pytest.fixture(scope="module")
def icub_run(tmp_path_factory):
    """simulate kinematics + stac (CLI, no --robot: the log names its robot directory)."""
    tmp = tmp_path_factory.mktemp("icub")
    rdir = erd.robot_dir(tmp, "icub_full", markers_per_link=1, seed=3)
    log = tmp / "k.h5"
    res = runner.invoke(
        app,
        [
            "simulate",
            "kinematics",
            "--robot",
            str(rdir),
            "-o",
            str(log),
            "--duration",
            "20",
            "--rate",
            "50",
            "--seed",
            "4",
            "-q",
        ],
    )
    assert res.exit_code == 0, res.output
    res = runner.invoke(app, ["stac", str(log)])
    assert res.exit_code == 0, res.output
    return rdir, log, tmp / "k.calib.yaml", res.output


def test_icub_half_markers_calibrates_what_the_data_determine(icub_run):
    rdir, log_path, calib, output = icub_run
    robot = load_robot(rdir)
    assert robot.n_joints == 32 and len(robot.sensors.markers) == 16
    log = load_log(log_path)
    truth = Calibration.from_dict(log.truth.params)
    cal = Calibration.from_dict(load_yaml(calib))
    obs = Observation(log.without_truth(), robot)
    obs.check_observable()
    # the head's yaw moves no marker: its pot keeps the nominal values, exactly, and is listed
    unobservable = {u["pot"]: u for u in cal.unobservable}
    assert set(unobservable) == {"neck_yaw_pot"}
    assert unobservable["neck_yaw_pot"]["reason"] == "no marker moves with joint neck_yaw"
    nominal = {p.name: p for p in robot.sensors.pots}
    i = cal.pot_names.index("neck_yaw_pot")
    assert cal.gain[i] == nominal["neck_yaw_pot"].gain and cal.bias[i] == nominal["neck_yaw_pot"].bias
    assert np.isnan(cal.gain_se[i]) and np.isnan(cal.bias_se[i])
    assert abs(truth.gain[i] / cal.gain[i] - 1) > 0.01  # it really is not calibrated
    # the other 31 gains and the biases not fixed by a gauge recover the truth within their SEs
    ok = np.array([n != "neck_yaw_pot" for n in cal.pot_names])
    z_gain = (cal.gain - truth.gain) / cal.gain_se
    assert np.all(np.abs(z_gain[ok]) < 4.5), z_gain
    assert np.median(np.abs(cal.gain / truth.gain - 1)[ok]) < 0.005  # (a foot's marker near its ankle: ~5 %)
    free = ok & ~obs.fixed_bias
    b_equiv = obs.gauge_equivalent_bias(truth.gain, truth.bias, cal.bias)
    z_bias = (cal.bias - b_equiv) / cal.bias_se
    assert np.all(np.abs(z_bias[free]) < 4.5), z_bias
    assert np.median(np.abs((cal.bias - b_equiv) / truth.gain)[free]) < 0.005  # rad
    markers = np.linalg.norm(cal.marker_xyz - truth.marker_xyz, axis=1)[obs.gauge_free_markers()]
    assert markers.max() < 0.003
    # gauges: every leaf joint's zero, one bias kept nominal each, with the reason in words
    gauges = {g["joint"]: g for g in cal.gauges}
    assert {"l_wrist_yaw", "r_wrist_yaw"} <= set(gauges)
    for joint, g in gauges.items():
        assert g["kind"] in ("leaf", "root") and joint in g["reason"]
        assert cal.bias[cal.pot_names.index(g["pot"])] == nominal[g["pot"]].bias
    # a leaf gauge's markers are turned about its axis: their distance from it and place along it are the data's
    turned = {m: g["joint"] for g in cal.gauges for m in g.get("markers", ())}
    assert set(turned) == {m for m, free in zip(cal.marker_names, obs.gauge_free_markers(), strict=True) if not free}
    axes = gauge_axes(robot, set(turned.values()))
    for m in turned:
        i, (_, a) = cal.marker_names.index(m), axes[m]
        place = robot.model.frames[robot.frame_id(cal.marker_links[i])].placement
        origin = -place.rotation.T @ place.translation
        fit, true = (x - origin for x in (cal.marker_xyz[i], truth.marker_xyz[i]))
        radius = np.linalg.norm(np.cross(a, fit)) - np.linalg.norm(np.cross(a, true))
        assert abs(a @ fit - a @ true) < 0.003 and abs(radius) < 0.003, (m, np.linalg.norm(fit - true))


def test_icub_coverage_is_said_once_in_the_summary_and_the_report(icub_run):
    _, _, calib, output = icub_run
    warnings = [line for line in output.splitlines() if line.startswith("warning:")]
    assert len(warnings) == 1 and "neck_yaw_pot" in warnings[0] and "unobservable" in warnings[0]
    assert "unobservable (nominal)" in output and "gauges (bias nominal)" in output
    data = load_yaml(calib)
    assert data["unobservable"][0]["pot"] == "neck_yaw_pot" and data["gauges"]
    opening = " ".join(abstract(calib, ReportContext()))  # the report's words
    assert "1 pot(s) (neck_yaw_pot) keep their nominal gain and bias: no marker moves with their joints" in opening
    assert "held at nominal because the markers cannot fix that joint's zero" in opening
    _, rows, _ = pot_table(Calibration.from_dict(data), None)  # the report's pot table
    notes = {r[0]: r[-1] for r in rows}
    assert notes["neck_yaw_pot"] == "nominal: unobservable"
    assert {notes[g["pot"]] for g in data["gauges"]} == {"bias nominal: gauge"}
    turned = {m: g["joint"] for g in data["gauges"] for m in g.get("markers", ())}
    _, rows, _ = marker_table(Calibration.from_dict(data), None)
    assert turned and {r[0]: r[-1] for r in rows if r[-1]} == {m: f"gauge: {j}" for m, j in turned.items()}
    assert f"the positions of {', '.join(turned)} are placed turned about their joint's axis" in opening
