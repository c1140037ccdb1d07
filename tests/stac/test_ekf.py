"""EKF tracking and calibration over [θ, q] (thesis §2.4.1, eq. 2.24-2.27) vs simulator truth."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import synth

from diegocal.errors import FitError
from diegocal.stac import Calibration, StacOptions
from diegocal.stac.classical import ThetaLayout
from diegocal.stac.ekf import EkfOptions, _Filter, calibrate_ekf

ROTARY_CHAINS = (("arm", "rrrr"), ("leg", "rrr"))
NOISE = {"sigma_pots": 0.002, "sigma_markers": 0.001}


@pytest.fixture(scope="module")
def rotary_robot(tmp_path_factory):
    return synth.load(synth.make_tree_robot(tmp_path_factory.mktemp("ekf"), ROTARY_CHAINS, seed=1))


def _seeded(truth, rng, gain_rel, bias, xyz):
    """A seed around the truth: the thesis's Fig. 2.7 protocol (seeding error injected)."""
    return replace(
        truth,
        gain=truth.gain * (1 + rng.normal(0, gain_rel, truth.gain.shape)),
        bias=truth.bias + rng.normal(0, bias, truth.bias.shape),
        marker_xyz=truth.marker_xyz + rng.normal(0, xyz, truth.marker_xyz.shape),
    )


def test_converges_from_a_good_seed_on_low_noise(rotary_robot):
    log = synth.simulate(rotary_robot, n_frames=400, seed=3, occlusion=0.1, **NOISE)
    truth = Calibration.from_dict(log.truth.params)
    q_true = log.truth.signals["q"].data
    rng = np.random.default_rng(0)
    seed = _seeded(truth, rng, 0.05, 0.05, 0.01)
    opts = EkfOptions(
        sigma_pots=NOISE["sigma_pots"],
        sigma_markers=NOISE["sigma_markers"],
        q_step=0.05,
        seed_gain_rel=0.05,
        seed_bias=0.05,
        seed_xyz=0.01,
        seed_rot=0.01,
        seed_trans=0.01,
    )
    # the thesis starts the filter at the true first-frame joint angles (§2.6.2)
    res = calibrate_ekf(log.without_truth(), rotary_robot, StacOptions(), ekf=opts, seed=seed, q0=q_true[0])
    cal = res.calibration
    assert cal.method == "ekf" and cal.fit.converged and np.isfinite(res.q).all()
    gain_err = np.abs(cal.gain - truth.gain) / truth.gain
    seed_gain_err = np.abs(seed.gain - truth.gain) / truth.gain
    xyz_err = np.linalg.norm(cal.marker_xyz - truth.marker_xyz, axis=1)
    seed_xyz_err = np.linalg.norm(seed.marker_xyz - truth.marker_xyz, axis=1)
    print(
        f"EKF gain error {gain_err.mean():.4f} (seed {seed_gain_err.mean():.4f}), "
        f"marker error {xyz_err.mean() * 1000:.2f} mm (seed {seed_xyz_err.mean() * 1000:.2f} mm)"
    )
    assert gain_err.mean() < 0.3 * seed_gain_err.mean() and gain_err.max() < 0.02
    assert xyz_err.mean() < 0.5 * seed_xyz_err.mean()
    # tracking: once settled, joint angles beat those the seed calibration reads off the pots
    # (weakly identified biases — a single marker below a joint — keep part of their seed error)
    pots = log.streams["pots"].data
    q_seed = (pots - seed.bias) / seed.gain
    settled = np.median(np.abs(res.q[200:] - q_true[200:]))
    assert settled < 0.5 * np.median(np.abs(q_seed[200:] - q_true[200:])) and settled < 0.02
    # the innovation RMS estimates the injected noise levels
    assert cal.sigma_markers < 3 * NOISE["sigma_markers"]
    # standard errors come from the filter covariance and shrink below the prior
    layout = ThetaLayout.for_robot(rotary_robot)
    assert np.all(cal.gain_se[layout.gain_pots] < 0.05 * np.abs(seed.gain[layout.gain_pots]))


def test_observation_jacobian_matches_finite_differences(tree_robot):
    """eq. 2.27: analytic blocks (pots, markers wrt θ and q) = central differences, with gimbals."""
    log = synth.simulate(tree_robot, n_frames=2, seed=1)
    truth = Calibration.from_dict(log.truth.params)
    layout = ThetaLayout.for_robot(tree_robot)
    filt = _Filter(tree_robot, layout, truth, EkfOptions())
    z = np.concatenate([layout.pack(truth), log.truth.signals["q"].data[0]])
    visible = np.ones(3 * layout.n_markers, bool)
    visible[:3] = False  # an occluded marker drops its rows
    h, H = filt.observe(z, visible)
    assert H.shape == (len(tree_robot.sensors.pots) + visible.sum(), z.size) and h.shape == H.shape[:1]
    fd = np.empty_like(H)
    for k in range(z.size):
        step = 1e-6 * max(1.0, abs(z[k]))
        up, dn = z.copy(), z.copy()
        up[k] += step
        dn[k] -= step
        fd[:, k] = (filt.observe(up, visible)[0] - filt.observe(dn, visible)[0]) / (2 * step)
    np.testing.assert_allclose(H, fd, atol=1e-6 * np.abs(fd).max())


def test_divergence_is_reported_not_raised(rotary_robot):
    log = synth.simulate(rotary_robot, n_frames=30, seed=2, **NOISE).without_truth()
    nominal = Calibration.nominal(rotary_robot)
    broken = replace(nominal, gain=np.full_like(nominal.gain, np.nan))
    res = calibrate_ekf(log, rotary_robot, seed=broken, q0=np.zeros(rotary_robot.n_joints))
    assert not res.calibration.fit.converged
    assert np.isnan(res.q).all()
    assert res.history[-1].cost == float("inf")


def test_does_not_read_truth(rotary_robot):
    log = synth.simulate(rotary_robot, n_frames=40, seed=6, **NOISE)
    a = calibrate_ekf(log, rotary_robot).calibration
    b = calibrate_ekf(log.without_truth(), rotary_robot).calibration
    np.testing.assert_array_equal(a.gain, b.gain)
    np.testing.assert_array_equal(a.marker_xyz, b.marker_xyz)


def test_bad_noise_options_and_seed_sd(rotary_robot):
    log = synth.simulate(rotary_robot, n_frames=5, seed=2).without_truth()
    with pytest.raises(FitError, match="noise levels must be positive"):
        calibrate_ekf(log, rotary_robot, ekf=EkfOptions(sigma_markers=0.0))
    with pytest.raises(FitError, match="seed_sd: expected shape"):
        calibrate_ekf(log, rotary_robot, seed_sd=np.ones(3))


def test_cli_method_ekf_end_to_end(tmp_path, rotary_robot):
    """`diegocal stac LOG --method ekf` writes calib.yaml (method ekf) with the filter estimate."""
    from typer.testing import CliRunner

    from diegocal.cli import app
    from diegocal.io import load_yaml, save_log

    log = synth.simulate(rotary_robot, n_frames=60, seed=8, **NOISE)
    path = tmp_path / "ekf.h5"
    save_log(log, path)
    out = tmp_path / "ekf.calib.yaml"
    args = ["stac", str(path), "--robot", str(rotary_robot.directory), "--method", "ekf", "--quiet"]
    res = CliRunner().invoke(app, [*args, "-o", str(out)])
    assert res.exit_code == 0, res.output
    cal = Calibration.from_dict(load_yaml(out))
    assert cal.method == "ekf" and cal.gain.shape == (len(rotary_robot.sensors.pots),)
    assert np.isfinite(cal.gain).all()
