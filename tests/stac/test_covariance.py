"""STAC's standard errors (diegocal/stac/covariance.py): the profiled information and scores equal
their dense route, the block sandwich covers the truth when the marker noise is correlated in time
(where the model-based covariance does not), and calib.yaml writes the parameters that trade off
beside their values, readable by a reader that does not know the key (issue #31 item 5)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import synth

from diegocal.stac import calibrate
from diegocal.stac.calibration import Calibration
from diegocal.stac.covariance import covariance, information
from diegocal.stac.joint_step import _dense_q_jacobian, _theta_jacobian
from diegocal.stac.model import Observation
from diegocal.stac.qphase import Noise, damped, normal_equations, pot_sigmas
from diegocal.terms import term_from_dict


def _fit(robot, seed, marker_time=0.0, n_frames=2000):
    log = synth.simulate(robot, n_frames, seed=seed, marker_time=marker_time)
    res = calibrate(log.without_truth(), robot)
    obs = Observation(log.without_truth(), robot)
    obs.check_observable()
    cal = res.calibration
    noise = Noise(pot_sigmas(obs, cal.sigma_by_group), cal.sigma_by_group["markers"])
    return log, res, obs, obs.params_from(cal), noise


def _z(log, obs, cal) -> np.ndarray:
    """(estimate − truth) / SE of the gains, the biases (in the fit's gauge) and the markers that
    take up no gauge."""
    truth = Calibration.from_dict(log.truth.params)
    b = obs.gauge_equivalent_bias(truth.gain, truth.bias, cal.bias)
    zx = (cal.marker_xyz - truth.marker_xyz) / cal.marker_xyz_se
    z = [
        (cal.gain - truth.gain) / cal.gain_se,
        ((cal.bias - b) / cal.bias_se)[~obs.fixed_bias],
        zx[obs.gauge_free_markers()].ravel(),
    ]
    z = np.concatenate(z)
    return z[np.isfinite(z)]


def test_profiled_information_and_scores_equal_the_dense_route(tree_robot):
    """A = Σ J_θᵀWJ_θ − BᵀH⁻¹B and g_t = (J_θ − J_q H⁻¹ B)ᵀ W z from the structured route equal the
    same products of the dense per-frame Jacobians (every frame: no subset)."""
    log, res, obs, params, noise = _fit(tree_robot, 3, n_frames=300)
    A, scores = information(obs, params, noise, res.q, batch=64, max_frames=10_000)
    sl = slice(0, 300)
    H, _, _, (s, Rl, pl), _, ex = normal_equations(obs, params, noise, res.q, sl, want_red=False)
    Jq, w = _dense_q_jacobian(obs, params, noise, res.q, ex["wp"], ex["wx"])
    Jt = _theta_jacobian(obs, params, noise, s, Rl, pl, ex["valid"])
    z = np.concatenate([ex["zp"], ex["rx"].reshape(300, -1)], axis=1)
    Hd = damped(H, np.zeros(300)).dense()
    dense_A, dense_g = 0.0, []
    for t in range(300):
        W = np.diag(w[t])
        P_t = Jt[t] - Jq[t] @ np.linalg.solve(Hd[t], Jq[t].T @ W @ Jt[t])
        dense_A = dense_A + Jt[t].T @ W @ P_t
        dense_g.append(P_t.T @ W @ z[t])
    assert np.allclose(A, dense_A, rtol=1e-8, atol=1e-8 * np.abs(dense_A).max())
    g = np.array(dense_g)
    assert np.allclose(-scores, g, rtol=1e-7, atol=1e-7 * np.abs(g).max())


def test_block_sums_as_made_equal_those_of_every_frames_scores(tree_robot):
    """The scores' block sums added a batch at a time (the blocks straddling batches, the last one
    short) are the same bits as ``np.add.reduceat`` over every frame's scores."""
    log, res, obs, params, noise = _fit(tree_robot, 3, n_frames=300)
    A, scores = information(obs, params, noise, res.q, batch=64, max_frames=100)
    for length in (7, 10, 64, 100, 300):
        A2, sums = information(obs, params, noise, res.q, batch=64, max_frames=100, length=length)
        np.testing.assert_array_equal(A2, A)
        np.testing.assert_array_equal(sums, np.add.reduceat(scores, np.arange(0, 300, length), axis=0))


def test_block_sandwich_covers_the_truth_under_correlated_marker_noise(tree_robot):
    """Marker noise with a 50 ms correlation time (the reconstruction's smoothing at 100 Hz): the
    model-based standard errors (independent frames) cover the truth within 2 SE for little more
    than half of the estimates; the reported ones (the block sandwich) for 88 % or more. With white
    noise both cover it (the reported ones are never below the model's)."""
    z_model, z_reported, z_white = [], [], []
    for seed in range(6):
        log, res, obs, params, noise = _fit(tree_robot, seed, marker_time=0.05)
        cal = res.calibration
        cov = covariance(obs, params, noise, res.q)
        P, M = obs.n_pots, obs.n_markers
        sd = np.full(cov.free.size, np.nan)
        sd[cov.free] = np.sqrt(np.diag(cov.model))
        xyz_se = sd[2 * P : 2 * P + 3 * M].reshape(M, 3)
        model = replace(cal, gain_se=sd[:P], bias_se=sd[P : 2 * P], marker_xyz_se=xyz_se)
        z_model.append(_z(log, obs, model))
        z_reported.append(_z(log, obs, cal))
        assert cal.stderr["method"] == "block_sandwich" and cal.stderr["blocks"] == 40
    for seed in range(3):
        log, res, obs, _, _ = _fit(tree_robot, 10 + seed)
        z_white.append(_z(log, obs, res.calibration))
    within = {
        k: float(np.mean(np.abs(np.concatenate(v)) <= 2))
        for k, v in (("model", z_model), ("reported", z_reported), ("white", z_white))
    }
    assert within["model"] < 0.75, within
    assert within["reported"] >= 0.88, within
    assert within["white"] >= 0.88, within


def test_correlated_estimates_are_written_beside_their_values(tree_robot, tmp_path):
    """A pot's gain and bias trade off when its joint stays on one side of zero: the pair is in
    Calibration.correlations and in calib.yaml's baseline beside each value ({value, stderr, unit,
    correlated}); read back the same, and a reader that knows only {value, stderr, unit} reads
    the values and standard errors unchanged."""
    log, res, obs, _, _ = _fit(tree_robot, 4)
    cal = res.calibration
    assert cal.correlations, "no pair trades off"
    a, b, rho = cal.correlations[0]
    assert abs(rho) >= 0.9
    data = cal.to_dict()
    pots = {d["channel"]: d for d in data["baseline"] if d["cause"] == "pot_transfer"}
    markers = {d["channel"]: d for d in data["baseline"] if d["cause"] == "marker_position"}
    channel, name = a.rsplit(".", 1)
    entry = (pots.get(channel) or markers[channel])["parameters"][name]
    assert entry["correlated"][b] == pytest.approx(rho, abs=1e-3)
    assert set(entry) == {"value", "stderr", "unit", "correlated"}
    back = Calibration.from_dict(data)
    assert {(x, y) for x, y, _ in back.correlations} == {(x, y) for x, y, _ in cal.correlations}
    assert back.stderr == cal.stderr
    old = [term_from_dict(d, "calib.yaml", "kinematics") for d in data["baseline"]]
    assert np.allclose([t.values[0] for t in old if t.cause == "pot_transfer"], cal.gain)
    assert np.allclose([t.stderrs[0] for t in old if t.cause == "pot_transfer"], cal.gain_se, equal_nan=True)


def test_the_markers_covariance_agrees_with_their_standard_errors(tree_robot):
    """Calibration.marker_xyz_cov (2, 3M, 3M), reported and model-based: each symmetric and
    positive semi-definite, the reported's diagonal the squares of marker_xyz_se, which is never
    below the model-based one (what a function of several coordinates, a slip's move, needs)."""
    _, res, _, _, _ = _fit(tree_robot, 4)
    cal = res.calibration
    reported, model = cal.marker_xyz_cov
    assert reported.shape == (cal.marker_xyz.size,) * 2 and np.isfinite(cal.marker_xyz_cov).all()
    np.testing.assert_allclose(np.diag(reported), cal.marker_xyz_se.ravel() ** 2, rtol=1e-10)
    assert np.all(np.diag(model) <= np.diag(reported) * (1 + 1e-10))
    for cov in (reported, model):
        np.testing.assert_allclose(cov, cov.T, rtol=1e-12, atol=1e-18)
        assert np.linalg.eigvalsh(cov).min() > -1e-12 * np.abs(cov).max()
