"""STAC recovers what the simulator injected (parameters within a few standard errors), tracks q,
survives occlusion, and predicts held-out data across sensors (thesis §2.6-2.7)."""

import numpy as np
import pytest
import synth
from scipy.spatial.transform import Rotation

from diegocal.errors import FitError
from diegocal.stac.calibration import Calibration
from diegocal.stac.model import Observation
from diegocal.stac.pphase import kabsch
from diegocal.stac.predict import predict
from diegocal.stac.result import StacOptions
from diegocal.stac.stac import _aitken, calibrate

Z = 4.5  # standard errors allowed per parameter (a few hundred parameters in all)


def _check_recovery(robot, log, result):
    truth = Calibration.from_dict(log.truth.params)
    cal = result.calibration
    # pots whose bias is estimated, markers whose position takes up no gauge
    obs = Observation(log, robot)
    obs.check_observable()
    bias_free, marker_free, fixed_joints = ~obs.fixed_bias, obs.gauge_free_markers(), obs.gauge_joints()
    zg = (cal.gain - truth.gain) / cal.gain_se
    assert np.all(np.abs(zg) < Z), f"gain z-scores {np.round(zg, 1)}"
    # gauge-equivalent true biases: fixing pot j's bias at nominal shifts q_k by
    # δ = (b_true − b_nominal) / gain and every other pot reading q_k (tendons) by −gain r δ
    b_equiv = obs.gauge_equivalent_bias(truth.gain, truth.bias, cal.bias)
    zb = ((cal.bias - b_equiv) / cal.bias_se)[bias_free]
    assert np.all(np.abs(zb) < Z), f"bias z-scores {np.round(zb, 1)}"
    zx = ((cal.marker_xyz - truth.marker_xyz) / cal.marker_xyz_se)[marker_free]
    assert np.all(np.abs(zx) < Z), f"marker z-scores {np.round(zx, 1)}"
    assert np.all(cal.gain_se < 0.05 * np.abs(truth.gain))  # the SEs are informative, not huge
    q_true = log.truth.signals["q"].data
    free_q = [i for i, n in enumerate(robot.joint_names) if n not in fixed_joints]
    rmse = np.sqrt(np.mean((result.q[:, free_q] - q_true[:, free_q]) ** 2))
    # per-frame noise (~0.005 rad) plus each joint's zero, known to its pot's bias SE / gain
    allowed = 0.01 + 2 * np.nanmax(np.abs(cal.bias_se / cal.gain)[bias_free])
    assert rmse < allowed, f"joint-angle RMSE {rmse:.4f} rad (allowed {allowed:.4f})"
    return rmse


@pytest.fixture(scope="module")
def tree_fit(tree_robot):
    log = synth.simulate(tree_robot, 600, seed=11)
    return log, calibrate(log.without_truth(), tree_robot, StacOptions(max_iterations=40))


def test_kabsch_recovers_a_proper_rotation():
    rng = np.random.default_rng(0)
    R = Rotation.from_rotvec([0.3, -1.0, 0.5]).as_matrix()
    xb = rng.normal(size=(50, 3))
    x = xb @ R.T + [1.0, 2.0, 3.0]
    R_hat, T_hat = kabsch(xb, x, np.ones(50))
    np.testing.assert_allclose(R_hat, R, atol=1e-12)
    np.testing.assert_allclose(T_hat, [1.0, 2.0, 3.0], atol=1e-12)
    # mirrored data: the best *proper* rotation, never a reflection (eq. 2.15 replaced)
    R_m, _ = kabsch(xb, x * [1, 1, -1], np.ones(50))
    assert np.linalg.det(R_m) == pytest.approx(1.0)


def test_tree_robot_parameters_within_standard_errors(tree_robot, tree_fit):
    log, result = tree_fit
    _check_recovery(tree_robot, log, result)
    assert result.calibration.fit.converged
    costs = [h.cost for h in result.history]
    assert costs[-1] < costs[0]


def test_gimbal_linear_pots_recovered(tree_robot, tree_fit):
    log, result = tree_fit
    truth = Calibration.from_dict(log.truth.params)
    cal = result.calibration
    lin = [i for i, p in enumerate(tree_robot.sensors.pots) if p.kind == "linear"]
    assert lin
    np.testing.assert_allclose(cal.gain[lin], truth.gain[lin], rtol=0.02)
    assert np.all(np.abs(cal.bias[lin] - truth.bias[lin]) < Z * cal.bias_se[lin])


def test_noise_levels_estimated_per_sensor_type(tree_fit):
    _, result = tree_fit
    s = result.calibration.sigma_by_group
    assert s["rotary"] == pytest.approx(0.005, rel=0.25)
    assert s["linear"] == pytest.approx(0.005, rel=0.35)
    assert s["markers"] == pytest.approx(0.001, rel=0.25)


def test_occluded_markers_converge_to_the_same_answer(tree_robot, tree_fit):
    log, result = tree_fit
    mk = log.streams["markers"].data.copy()
    mk[np.random.default_rng(5).random(mk.shape[:2]) < 0.3] = np.nan
    occluded = log.with_streams(markers=synth.make_stream(log.streams["markers"].names, mk))
    res2 = calibrate(occluded.without_truth(), tree_robot, StacOptions(max_iterations=40))
    a, b = result.calibration, res2.calibration
    assert np.all(np.abs(a.gain - b.gain) < Z * b.gain_se)
    assert np.all(np.abs(a.marker_xyz - b.marker_xyz) < Z * b.marker_xyz_se + 1e-9)
    _check_recovery(tree_robot, occluded, res2)


def test_coarse_to_fine_reaches_the_full_data_optimum(tree_robot, tree_fit):
    """Converging on every third frame first, then on all frames, ends where the alternation on all
    frames ends (a small fraction of a standard error apart), in fewer full-data iterations."""
    log, result = tree_fit
    res = calibrate(log.without_truth(), tree_robot, StacOptions(max_iterations=40, coarse_frames=200))
    frames = [h.frames for h in res.history]
    assert frames[0] == 200 and frames[-1] == log.n_samples
    assert frames.count(log.n_samples) < len(result.history)
    a, b = result.calibration, res.calibration
    assert np.max(np.abs(b.gain - a.gain) / a.gain_se) < 0.2
    assert np.nanmax(np.abs(b.bias - a.bias) / a.bias_se) < 0.2
    assert np.nanmax(np.abs(b.marker_xyz - a.marker_xyz) / a.marker_xyz_se) < 0.2
    assert np.abs(res.q - result.q).max() < 1e-3
    for g, sigma in a.sigma_by_group.items():
        assert b.sigma_by_group[g] == pytest.approx(sigma, rel=2e-3)


def test_threads_give_the_same_answer(tree_robot, tree_fit):
    """--jobs runs batches of frames in threads; the result does not depend on it."""
    log, _ = tree_fit
    one, two = (
        calibrate(log.without_truth(), tree_robot, StacOptions(max_iterations=5, batch_size=100, jobs=j))
        for j in (1, 2)
    )
    np.testing.assert_array_equal(one.q, two.q)
    np.testing.assert_array_equal(one.calibration.gain, two.calibration.gain)
    np.testing.assert_array_equal(one.calibration.gain_se, two.calibration.gain_se)


def test_bad_schedule_options_raise(tree_robot, tree_fit):
    log, _ = tree_fit
    for bad in (StacOptions(coarse_frames=-1), StacOptions(batch_size=0)):
        with pytest.raises(FitError, match="coarse_frames"):
            calibrate(log.without_truth(), tree_robot, bad)


def test_aitken_extrapolates_a_geometric_tail():
    """σ iterates that shrink geometrically are extrapolated to their limit; others are kept."""
    limit, r = 0.005, 0.6
    seq = [{"a": limit * np.exp(0.2 * r**k), "b": 1.0 + 0.1 * (-1) ** k} for k in range(3)]
    out = _aitken(list(seq))
    assert out["a"] == pytest.approx(limit, rel=1e-12)
    assert out["b"] == seq[-1]["b"]  # oscillating: not extrapolated


def test_heldout_cross_sensor_prediction(tree_robot, tree_fit):
    log, result = tree_fit
    truth = Calibration.from_dict(log.truth.params)
    held = synth.simulate(tree_robot, 300, seed=12, truth=truth).without_truth()
    fitted = predict(held, tree_robot, result.calibration, ("pots",), ("markers",))
    nominal = predict(held, tree_robot, Calibration.nominal(tree_robot), ("pots",), ("markers",))
    # markers predicted from pots alone: a few mm (noise 1 mm/axis), far better than the seed
    assert fitted.mae["markers"] < 0.006
    assert nominal.mae["markers"] > 5 * fitted.mae["markers"]
    own = predict(held, tree_robot, result.calibration, ("markers",), ("markers", "rotary"))
    assert own.mae["markers"] < 0.003  # fit to the same sensor type (the thesis's parentheses)
    assert own.mae["rotary"] < 0.05


def test_tendon_finger(finger_robot):
    log = synth.simulate(finger_robot, 500, seed=21)
    result = calibrate(log.without_truth(), finger_robot, StacOptions(max_iterations=40))
    _check_recovery(finger_robot, log, result)
    tendons = [i for i, p in enumerate(finger_robot.sensors.pots) if p.kind == "tendon"]
    truth = Calibration.from_dict(log.truth.params)
    np.testing.assert_allclose(result.calibration.gain[tendons], truth.gain[tendons], rtol=0.03)
