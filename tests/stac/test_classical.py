"""Classical σp = 0 calibration (thesis §2.2.1, §2.4.2, eq. 2.28-2.29) against simulator truth.

Robots come from ``synth`` (tests/stac, put on the path by conftest.py); logs from the
project's kinematics simulator. Fitting code gets ``log.without_truth()``; truth is only
compared against afterwards.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import synth

from diegocal.errors import FitError, MissingStreamError
from diegocal.robot import BUNDLED_ROBOTS, load_robot, predict_markers
from diegocal.sim.kinematics import KinematicsOptions, simulate_kinematics
from diegocal.stac import Calibration, StacOptions
from diegocal.stac.classical import ThetaLayout, calibrate_classical, kabsch, packed_standard_errors
from diegocal.stac.pot_inverse import joint_angles_from_pots
from diegocal.stac.regression import MarkerRegression

ROTARY_CHAINS = (("arm", "rrrr"), ("leg", "rrr"))


@pytest.fixture(scope="module")
def rotary_robot(tmp_path_factory):
    return synth.load(synth.make_tree_robot(tmp_path_factory.mktemp("rot"), ROTARY_CHAINS, seed=1))


@pytest.fixture(scope="module")
def rotary_logs(rotary_robot):
    """Train and held-out logs of one robot (same truth), near-noise-free pots (σp ≈ 0 holds)."""
    opts = KinematicsOptions(duration=6.0, pot_noise=1e-4, marker_noise=0.001, occlusion=0.1)
    train = simulate_kinematics(rotary_robot, opts, np.random.default_rng(11))
    truth = Calibration.from_dict(train.truth.params)
    held = synth.simulate(rotary_robot, n_frames=300, seed=12, sigma_pots=1e-4, sigma_markers=0.001, truth=truth)
    return train, held, truth


def _gauge_entries(robot):
    """Pots whose bias markers cannot identify: all markers below their joint are on its child link.

    Rotating that link's markers about the joint axis trades exactly against the joint's bias, so
    the bias and the markers' in-plane coordinates form one unidentifiable direction.
    """
    parent = [robot.model.parents[k + 1] - 1 for k in range(robot.n_joints)]
    marker_joint = [robot.model.frames[robot.frame_id(m.link)].parentJoint - 1 for m in robot.sensors.markers]

    def below(j, k):  # is joint k joint j or one of its descendants
        while k >= 0:
            if k == j:
                return True
            k = parent[k]
        return False

    gauge = []
    for i, p in enumerate(robot.sensors.pots):
        j = robot.joint_index(p.joint)
        under = [k for k in marker_joint if below(j, k)]
        if under and all(k == j for k in under):
            gauge.append(i)
    return gauge


def test_recovers_rotary_robot_within_standard_errors(rotary_robot, rotary_logs):
    train, held, truth = rotary_logs
    res = calibrate_classical(train.without_truth(), rotary_robot, StacOptions())
    cal = res.calibration
    assert cal.method == "classical" and cal.fit.converged
    gauge = _gauge_entries(rotary_robot)
    assert gauge, "the test robot should have leaf-joint gauge freedoms"
    ident = [i for i in range(len(cal.gain)) if i not in gauge]
    # gains are identifiable everywhere, biases except the gauge joints (flagged NaN)
    z_gain = (cal.gain - truth.gain) / cal.gain_se
    z_bias = (cal.bias[ident] - truth.bias[ident]) / cal.bias_se[ident]
    assert np.all(np.abs(z_gain) < 4.5), z_gain
    assert np.all(np.abs(z_bias) < 4.5), z_bias
    assert np.isnan(cal.bias_se[gauge]).all()
    assert np.isfinite(cal.bias_se[ident]).all()
    # marker coordinates whose standard error is finite are recovered within a few of them
    ok = np.isfinite(cal.marker_xyz_se)
    z_xyz = (cal.marker_xyz - truth.marker_xyz)[ok] / cal.marker_xyz_se[ok]
    assert ok.sum() == ok.size - 2 * len(gauge) and np.all(np.abs(z_xyz) < 4.5), z_xyz
    rot_err = np.degrees(np.arccos(np.clip((np.trace(cal.mocap_R.T @ truth.mocap_R) - 1) / 2, -1, 1)))
    assert rot_err < 0.5
    assert abs(cal.sigma_markers - 0.001) < 0.0003
    # held-out data: markers predicted from pots reach the marker noise, far below nominal
    pots, mk = held.streams["pots"].data, held.streams["markers"].data
    assert _mae(rotary_robot, cal, pots, mk) < 0.002
    nominal = replace(Calibration.nominal(rotary_robot), mocap_R=cal.mocap_R, mocap_T=cal.mocap_T)
    assert _mae(rotary_robot, nominal, pots, mk) > 5 * _mae(rotary_robot, cal, pots, mk)


def _mae(robot, cal, pots, markers):
    """Mean marker distance (m) when markers are predicted from pots alone (thesis Table 2.2)."""
    q = joint_angles_from_pots(robot, cal, pots).q
    err = np.linalg.norm(predict_markers(robot, q, cal.marker_xyz, cal.mocap_R, cal.mocap_T) - markers, axis=-1)
    return float(np.nanmean(err))


def test_does_not_read_truth(rotary_robot, rotary_logs):
    train = rotary_logs[0]
    short = train.slice(0, 200)
    a = calibrate_classical(short, rotary_robot, StacOptions(max_iterations=5)).calibration
    b = calibrate_classical(short.without_truth(), rotary_robot, StacOptions(max_iterations=5)).calibration
    np.testing.assert_array_equal(a.gain, b.gain)
    np.testing.assert_array_equal(a.marker_xyz, b.marker_xyz)


@pytest.mark.parametrize("robot_name", ["diego", "finger"])
def test_refuses_linear_and_tendon_pots_by_name(robot_name):
    robot = load_robot(BUNDLED_ROBOTS / robot_name)
    hard = [p.name for p in robot.sensors.pots if p.kind in ("linear", "tendon")]
    assert hard
    log = synth.simulate(robot, n_frames=5, seed=0)
    with pytest.raises(FitError) as info:
        calibrate_classical(log.without_truth(), robot)
    msg = str(info.value)
    assert "cannot handle linear/tendon pots" in msg and "--method stac" in msg
    assert all(name in msg for name in hard)
    assert "\n" not in msg


def test_bad_options_and_missing_streams(rotary_robot, rotary_logs):
    log = rotary_logs[0].without_truth()
    with pytest.raises(FitError, match="nonlinear='bogus'"):
        calibrate_classical(log, rotary_robot, nonlinear="bogus")
    no_markers = replace(log, streams={"pots": log.streams["pots"]})
    with pytest.raises(MissingStreamError, match="no 'markers' stream"):
        calibrate_classical(no_markers, rotary_robot)
    with pytest.raises(FitError, match="at least 2 samples"):
        calibrate_classical(log.slice(0, 1), rotary_robot)


def test_held_pots_keep_their_nominal_values(rotary_robot, rotary_logs):
    """hold=(names): those pots are not calibrated (nominal values, no standard error), the rest are."""
    train, _, truth = rotary_logs
    held = rotary_robot.sensors.pot_names[:2]
    cal = calibrate_classical(train.without_truth(), rotary_robot, hold=held).calibration
    nominal = Calibration.nominal(rotary_robot)
    np.testing.assert_array_equal(cal.gain[:2], nominal.gain[:2])
    np.testing.assert_array_equal(cal.bias[:2], nominal.bias[:2])
    assert np.isnan(cal.gain_se[:2]).all() and np.isfinite(cal.gain_se[2:]).all()
    with pytest.raises(FitError, match="'nope' is not a pot"):
        calibrate_classical(train.without_truth(), rotary_robot, hold=("nope",))


def test_normal_equations_match_finite_differences_through_gimbal_constraints(tree_robot):
    """JᵀWJ and JᵀW r summed per marker block (implicit-function step for gimbal pots) equal
    those of the central-difference Jacobian of the residuals, in batches smaller than the log."""
    log = synth.simulate(tree_robot, n_frames=6, seed=4, sigma_pots=0.0, occlusion=0.2)
    pots, mk = log.streams["pots"].data, log.streams["markers"].data
    truth = Calibration.from_dict(log.truth.params)
    layout = ThetaLayout.for_robot(tree_robot)
    problem = MarkerRegression(tree_robot, layout, truth, pots, mk, log.truth.signals["q"].data, batch=4)
    x0 = layout.pack(truth) + np.random.default_rng(0).normal(0, 1e-3, layout.size)
    fd = np.empty((problem.residual(x0).size, layout.size))
    for k in range(layout.size):
        h = 1e-6 * max(1.0, abs(x0[k]))
        up, dn = x0.copy(), x0.copy()
        up[k] += h
        dn[k] -= h
        fd[:, k] = (problem.residual(up) - problem.residual(dn)) / (2 * h)
    r = problem.residual(x0)
    w = np.random.default_rng(1).uniform(0.2, 1.0, r.size)
    A, g = problem.normal_equations(x0, w)
    np.testing.assert_allclose(A, fd.T @ (fd * w[:, None]), atol=1e-6 * np.abs(A).max())
    np.testing.assert_allclose(g, fd.T @ (w * r), atol=1e-6 * np.abs(g).max())


def test_constrained_gimbals_recover_parameters(tree_robot):
    """nonlinear='constrain' (eq. 2.28 solved by numerical inverse kinematics) on a gimbal robot.

    From a good seed (5 % gain, 0.05 rad bias errors) with near-noise-free pots the fit reaches
    the marker noise and every identifiable parameter lies within a few standard errors of the
    truth. (From the simulator's default 20 % seeding error it can stop in a local minimum:
    see bench/bench_stac_compare.py.)
    """
    rng = np.random.default_rng(5)
    truth = synth.true_calibration(tree_robot, rng, gain_err=0.05, bias_err=0.05)
    log = synth.simulate(
        tree_robot,
        n_frames=250,
        seed=5,
        sigma_pots=1e-5,
        sigma_markers=0.001,
        occlusion=0.1,
        truth=truth,
    )
    cal = calibrate_classical(log.without_truth(), tree_robot, nonlinear="constrain").calibration
    assert abs(cal.sigma_markers - 0.001) < 0.0002
    for est, se, true in (
        (cal.gain, cal.gain_se, truth.gain),
        (cal.bias, cal.bias_se, truth.bias),
        (cal.marker_xyz, cal.marker_xyz_se, truth.marker_xyz),
    ):
        ok = np.isfinite(se)
        assert ok.mean() > 0.6
        z = (est - true)[ok] / se[ok]
        assert np.all(np.abs(z) < 4.5), z
    linear = [i for i, p in enumerate(tree_robot.sensors.pots) if p.kind == "linear"]
    assert np.isfinite(cal.gain_se[linear]).all()
    # 'nominal' holds the gimbal pots at their nominal values and reports no standard error
    held = calibrate_classical(log.without_truth(), tree_robot, nonlinear="nominal").calibration
    assert np.all(held.gain[linear] == Calibration.nominal(tree_robot).gain[linear])
    assert np.isnan(held.gain_se[linear]).all()


def test_kabsch_recovers_a_rotation_and_guards_reflections():
    rng = np.random.default_rng(3)
    a = rng.normal(size=(20, 3))
    from scipy.spatial.transform import Rotation

    R = Rotation.random(random_state=rng).as_matrix()
    R_hat, T_hat = kabsch(a, a @ R.T + [1.0, 2.0, 3.0])
    np.testing.assert_allclose(R_hat, R, atol=1e-12)
    np.testing.assert_allclose(T_hat, [1.0, 2.0, 3.0], atol=1e-12)
    R_m, _ = kabsch(a, -a)  # a reflection is not a rotation
    assert np.linalg.det(R_m) > 0


def test_standard_errors_flag_the_null_space():
    J = np.array([[1.0, 1.0, 0.0], [2.0, 2.0, 0.0], [0.0, 0.0, 3.0], [1.0, 1.0, 1.0]])
    se = packed_standard_errors(J.T @ J, 1.0)
    assert np.isnan(se[:2]).all() and np.isclose(se[2], np.sqrt(np.linalg.inv(J[:, 1:].T @ J[:, 1:])[1, 1]))


@pytest.mark.parametrize("name", ["finger", "diego"])
def test_batched_transmission_equals_the_robot_route(name):
    """transmission_jacobian (batched anchors) = diegocal.robot.pot_transmission_jacobian."""
    from diegocal.robot import pot_transmission_jacobian
    from diegocal.stac.pot_inverse import transmission_jacobian

    robot = load_robot(BUNDLED_ROBOTS / name)
    rng = np.random.default_rng(0)
    q = robot.lower + (robot.upper - robot.lower) * rng.uniform(0.1, 0.9, (5, robot.n_joints))
    s, ds = transmission_jacobian(robot, q)
    s_ref, ds_ref = pot_transmission_jacobian(robot, q)
    np.testing.assert_allclose(s, s_ref, atol=1e-12)
    np.testing.assert_allclose(ds, ds_ref, atol=1e-12)


def test_huber_loss_resists_marker_outliers(rotary_robot, rotary_logs):
    """loss='huber' (a second pass at huber_scale sigmas) beats plain least squares on outliers."""
    train, _, truth = rotary_logs
    mk = train.streams["markers"].data.copy()
    rng = np.random.default_rng(9)
    bad = rng.random(mk.shape[:2]) < 0.03  # 3 % mislabelled/ghost markers, 5-10 cm off
    mk[bad] += rng.uniform(0.05, 0.1, (bad.sum(), 3)) * rng.choice([-1, 1], (bad.sum(), 3))
    log = train.without_truth().with_streams(markers=replace(train.streams["markers"], data=mk))
    errs = {}
    for loss in ("linear", "huber"):
        cal = calibrate_classical(log, rotary_robot, StacOptions(loss=loss)).calibration
        errs[loss] = np.mean(np.abs(cal.gain - truth.gain))
    assert errs["huber"] < 0.5 * errs["linear"], errs


def test_cli_method_classical_end_to_end(tmp_path, rotary_robot, rotary_logs):
    """`diegocal stac LOG --method classical` writes calib.yaml near the truth; bad input fails."""
    from typer.testing import CliRunner

    from diegocal.cli import app
    from diegocal.io import load_yaml, save_log

    train, _, truth = rotary_logs
    path = tmp_path / "train.h5"
    save_log(train, path)
    out = tmp_path / "c.calib.yaml"
    args = ["stac", str(path), "--robot", str(rotary_robot.directory), "--method", "classical"]
    res = CliRunner().invoke(app, [*args, "-o", str(out), "--quiet"])
    assert res.exit_code == 0, res.output
    cal = Calibration.from_dict(load_yaml(out))
    assert cal.method == "classical"
    assert np.max(np.abs(cal.gain - truth.gain) / truth.gain) < 0.02
    no_markers = tmp_path / "pots_only.h5"
    save_log(replace(train, streams={"pots": train.streams["pots"]}), no_markers)
    res = CliRunner().invoke(
        app,
        [
            "stac",
            str(no_markers),
            "--robot",
            str(rotary_robot.directory),
            "--method",
            "classical",
            "--quiet",
        ],
    )
    assert res.exit_code != 0 and "no 'markers' stream" in res.output
