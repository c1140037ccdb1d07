"""``stac --geometry`` (issue #34): link geometry from static poses, against the truth of a
generator written apart from the estimator (experiments/static_geometry_generator.py: the
Pinocchio model's joint placements perturbed directly, encoders, tool points, noise)."""

import numpy as np
import pinocchio as pin
import pytest
import synth
from typer.testing import CliRunner

from diegocal.cli import app
from diegocal.errors import FitError
from diegocal.io import load_yaml, save_log
from diegocal.report.stac_pages import evaluate
from diegocal.robot import load_robot
from diegocal.robot.model import perturb_joint_placements
from diegocal.stac.calibration import Calibration
from diegocal.stac.geometry import calibrate_geometry
from diegocal.stac.geometry_model import State, layout, observe, pose_means
from diegocal.stac.predict import predict
from diegocal.stac.stac import calibrate

gen = pytest.importorskip("experiments.static_geometry_generator")
if not (gen.SHARE / gen.ROBOTS["panda"][0]).is_file():
    pytest.skip("example-robot-data is not installed", allow_module_level=True)

runner = CliRunner()


def z_scores(fit, params) -> np.ndarray:
    """(θ̂ − θ) / SE over the identifiable set, θ the truth of what it identifies: θ_kept + alias θ_dropped."""
    ident = fit.identifiability
    R_start = pin.exp3(-fit.value[3:6]) @ fit.calibration.mocap_R  # STAC's frame, the rotation's origin
    truth = gen.truth_of(fit.names, R_start, params)
    target = truth[ident.kept] + ident.alias @ truth[~ident.kept]
    return (fit.value[ident.kept] - target) / fit.stderr[ident.kept]


def held_out(robot, cal, test) -> tuple[float, float]:
    """Mean marker error of ``test`` predicted from its encoders, and its noise floor (the true model's)."""
    x = test.stream("markers").data
    err = np.linalg.norm(predict(test, robot, cal, ("pots",), ("markers",)).markers - x, axis=-1).mean()
    floor = np.linalg.norm(test.truth.signals["markers_floor"].data - x, axis=-1).mean()
    return float(err), float(floor)


@pytest.fixture(scope="module")
def panda(tmp_path_factory):
    out = tmp_path_factory.mktemp("panda")
    d, log = gen.simulate(out, gen.Session("panda", 60, 1, seed=3, hardware_seed=3))
    _, test = gen.simulate(out, gen.Session("panda", 40, 1, seed=103, hardware_seed=3))
    robot = load_robot(d)
    return robot, log, test, calibrate_geometry(log, robot)


def test_identifiable_set_follows_the_4r_rule(panda):
    """7 revolute joints seen through one point: 4·7 + 6 (frame) − 3 (the tool's orientation) = 31;
    each joint's rotation about its own axis is its encoder's zero (alias −1)."""
    robot, _, _, fit = panda
    ident = fit.identifiability
    assert ident.kept.sum() == 31 and len(fit.names) == 58
    assert np.isfinite(ident.condition) and ident.condition < 1e3
    dropped = {d["parameter"]: d["reason"] for d in fit.dropped}
    assert (
        "joint_geometry:panda_joint3.rz" in dropped
        and "-1·panda_joint3_enc.bias" in dropped["joint_geometry:panda_joint3.rz"]
    )
    assert all(f"joint_geometry:panda_joint1.{a}" in dropped for a in ("dx", "dy", "dz", "rx", "ry", "rz"))
    term = next(t for t in fit.calibration.terms if t.channel == "panda_joint3")
    assert term.cause == "joint_geometry" and "rz" in term.extra["dropped"] and np.isnan(term.stderrs[5])


def test_recovers_the_identifiable_geometry_within_its_standard_errors(panda):
    _, log, _, fit = panda
    z = z_scores(fit, log.truth.params)
    assert np.abs(z).max() < 3.0
    assert np.mean(np.abs(z) <= 2.0) >= 0.85
    assert 0.6 < np.std(z) < 1.4  # calibrated, neither inflated nor too small
    assert fit.sigma_markers == pytest.approx(log.truth.params["noise"]["markers"], rel=0.2)


def test_held_out_poses_are_predicted_at_the_noise_floor(panda):
    robot, log, test, fit = panda
    err, floor = held_out(robot, fit.calibration, test)
    assert err < 1.2 * floor
    stac_only, _ = held_out(robot, calibrate(log.without_truth(), robot).calibration, test)
    assert stac_only > 4.0 * floor  # the URDF's geometry is what STAC alone gets wrong


def test_jacobian_matches_finite_differences(panda):
    robot, log, _, fit = panda
    cal = fit.calibration
    lay = layout(robot, cal)
    data = pose_means(log.without_truth(), cal)
    rng = np.random.default_rng(0)
    state = State(
        cal.mocap_R, cal.mocap_T, cal.marker_xyz, cal.gain, cal.bias, rng.normal(0, 0.003, (len(lay.geometry), 6))
    )
    pots = data.pots[:4]
    x, J, _ = observe(robot, lay, state, cal.marker_links, pots)
    h = 1e-7
    for i in rng.choice(len(lay.names), 20, replace=False):
        e = np.zeros(len(lay.names))
        e[i] = h
        xp, _, _ = observe(robot, lay, state.step(lay, e), cal.marker_links, pots)
        xm, _, _ = observe(robot, lay, state.step(lay, -e), cal.marker_links, pots)
        np.testing.assert_allclose((xp - xm) / (2 * h), J[..., i], atol=2e-4, err_msg=lay.names[i])


def test_a_joint_geometry_term_moves_the_joint_as_the_generator_does(panda):
    """Two routes: diegocal's placement · SE3(exp(r), d) equals the generator's Translation · RPY."""
    robot, log, _, _ = panda
    g = log.truth.params["geometry"]
    mine = perturb_joint_placements(
        robot.model, {j: np.r_[v["xyz"], pin.log3(pin.rpy.rpyToMatrix(*v["rpy"]))] for j, v in g.items()}
    )
    theirs = gen.true_model(
        robot.model, {j: {"xyz": np.array(v["xyz"]), "rpy": np.array(v["rpy"])} for j, v in g.items()}
    )
    for j in g:
        jid = robot.model.getJointId(j)
        np.testing.assert_allclose(
            mine.jointPlacements[jid].homogeneous, theirs.jointPlacements[jid].homogeneous, atol=1e-12
        )


def test_calib_yaml_keeps_the_geometry_and_predict_uses_it(panda):
    robot, _, test, fit = panda
    back = Calibration.from_dict(fit.calibration.to_dict())
    assert [t.cause for t in back.terms] == ["joint_geometry"] * 7
    a = predict(test, robot, fit.calibration, ("pots",), ("markers",)).markers
    b = predict(test, robot, back, ("pots",), ("markers",)).markers
    np.testing.assert_allclose(a, b, atol=1e-9)


def test_mispaired_poses_are_written_off_and_stac_false_alarms_readmitted(tmp_path):
    d, log = gen.simulate(tmp_path, gen.Session("panda", 60, 3, wrong=6, seed=5, hardware_seed=5))
    fit = calibrate_geometry(log, load_robot(d))
    assert sorted(r["pose"] for r in fit.calibration.rejected_poses) == log.truth.params["wrong_poses"]
    assert fit.identifiability.kept.sum() == 37  # three points: the tool's frame seen, its 6 absorbed
    assert np.abs(z_scores(fit, log.truth.params)).max() < 3.5


def test_humanoid_torso_and_arm(tmp_path):
    """Talos's torso + left arm, 9 joints, one gripper point: the issue's real case in simulation."""
    d, log = gen.simulate(tmp_path, gen.Session("talos", 61, 1, seed=7, hardware_seed=7))
    _, test = gen.simulate(tmp_path, gen.Session("talos", 40, 1, seed=107, hardware_seed=7))
    robot = load_robot(d)
    fit = calibrate_geometry(log, robot)
    assert fit.identifiability.kept.sum() == 4 * 9 + 6 - 3
    err, floor = held_out(robot, fit.calibration, test)
    assert err < 1.2 * floor
    z = z_scores(fit, log.truth.params)
    assert np.abs(z).max() < 3.5 and np.mean(np.abs(z) <= 2.0) >= 0.85


def test_pot_gains_are_fitted_with_the_geometry(tmp_path):
    """Rotary pots (gain 1 ± 3 %) instead of encoders: each gain is one more identifiable parameter."""
    d, log = gen.simulate(tmp_path, gen.Session("panda", 60, 1, kind="rotary", seed=3, hardware_seed=3))
    _, test = gen.simulate(tmp_path, gen.Session("panda", 40, 1, kind="rotary", seed=103, hardware_seed=3))
    robot = load_robot(d)
    fit = calibrate_geometry(log, robot)
    assert fit.identifiability.kept.sum() == 31 + 7
    z = z_scores(fit, log.truth.params)
    assert np.abs(z).max() < 3.5 and np.mean(np.abs(z) <= 2.0) >= 0.85
    err, floor = held_out(robot, fit.calibration, test)
    assert err < 1.2 * floor


def test_too_few_poses_is_one_clear_error(tmp_path):
    d, log = gen.simulate(tmp_path, gen.Session("panda", 14, 1, seed=9))
    with pytest.raises(FitError, match="record more static poses"):
        calibrate_geometry(log, load_robot(d))
    save_log(log, tmp_path / "few.h5")
    res = runner.invoke(app, ["stac", str(tmp_path / "few.h5"), "--geometry", "-q"])
    assert res.exit_code == 1 and "record more static poses" in res.output
    assert "Traceback" not in res.output


def test_a_moving_log_is_refused_before_any_fit(tree_robot):
    with pytest.raises(FitError, match="needs static poses"):
        calibrate_geometry(synth.simulate(tree_robot, 300, seed=4), tree_robot)


def test_cli_geometry_cv_and_predict(tmp_path):
    d, log = gen.simulate(tmp_path, gen.Session("panda", 24, 3, seed=11, hardware_seed=11))
    _, test = gen.simulate(tmp_path, gen.Session("panda", 20, 3, seed=111, hardware_seed=11))
    save_log(log, tmp_path / "train.h5")
    save_log(test, tmp_path / "held.h5")
    out = tmp_path / "calib.yaml"
    res = runner.invoke(app, ["stac", str(tmp_path / "train.h5"), "--geometry", "--cv", "-o", str(out)])
    assert res.exit_code == 0, res.output
    assert "geometry: identifiable parameters" in res.output and "10 contiguous folds" in res.output
    data = load_yaml(out)
    assert data["geometry"]["identifiable"] == 37 and data["geometry"]["dropped"]
    # the summary's noise and pots calibrated are the geometry fit's, not STAC's start's
    g, table = data["geometry"], " ".join(res.output.split())
    assert f"σ markers (m), geometry fit │ {g['sigma_markers']:.4g}" in table
    assert f"σ pots (sensor unit), geometry fit │ {g['sigma_pots']:.4g}" in table
    assert f"pots calibrated (geometry fit) │ {len(g['pots'])} of 7" in table
    assert "σ encoder" not in table and g["pots"]
    assert data["cv"]["kind"] == "10 contiguous pose folds" and len(data["cv"]["poses"]) == 24
    assert data["cv"]["marker_error"]["median"] < 3e-3
    assert sum(t["cause"] == "joint_geometry" for t in data["terms"]) == 7
    res = runner.invoke(app, ["predict", str(out), str(tmp_path / "held.h5"), "-o", str(tmp_path / "p.h5")])
    assert res.exit_code == 0, res.output
    err, floor = held_out(load_robot(d), Calibration.from_dict(data), test)
    assert err < 1.3 * floor
    # the report's residuals on the fit log are the calibrated model's, its geometry included
    residuals, _ = evaluate(str(out), None, ()).residuals["markers"]
    assert np.sqrt(np.mean(residuals**2)) < 2 * floor
    res = runner.invoke(app, ["stac", str(tmp_path / "train.h5"), "--geometry", "--method", "classical"])
    assert res.exit_code == 2 and "--geometry is for --method stac" in res.output
