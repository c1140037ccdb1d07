"""Robust STAC (``loss='huber'`` / ``'tukey'``, :mod:`diegocal.stac.robust`): its losses and noise
level, and the calibration against simulator truth.

The simulator injects the two gross errors of a motion-capture session, ``swapped_labels`` and
``marker_outliers``; the same seed without them gives the clean log (the effects draw from their
own generators, so pots, markers and noise are otherwise identical). Tolerances come from the
noise: the standard errors of the fit to the clean log.
"""

import numpy as np
import pytest
from scipy.stats import chi2

from diegocal.robot import BUNDLED_ROBOTS, load_robot
from diegocal.sim import parse_effects
from diegocal.sim.kinematics import KinematicsOptions, simulate_kinematics
from diegocal.stac.calibration import Calibration
from diegocal.stac.model import Observation
from diegocal.stac.result import StacOptions
from diegocal.stac.robust import TUKEY_C, _kappa, group_sigma, rho, weight
from diegocal.stac.stac import calibrate

Z = 4.5  # standard errors allowed per parameter, as in test_stac.py


# ----------------------------------------------------------------------------- the losses
@pytest.mark.parametrize("loss", ["linear", "huber", "tukey"])
def test_weight_is_the_derivative_of_the_loss_over_z(loss):
    """IRLS weight w(z) = ρ'(z) / z: central differences of ρ (two routes agree)."""
    z = np.linspace(0.05, 2 * TUKEY_C, 400)
    h = 1e-6
    d = (rho(z + h, loss, 3.0) - rho(z - h, loss, 3.0)) / (2 * h)
    np.testing.assert_allclose(weight(z, loss, 3.0), d / z, atol=1e-6)
    if loss == "tukey":  # redescending: no weight, and a constant loss, past c
        far = z[z > TUKEY_C]
        assert np.all(weight(far, loss, 3.0) == 0.0)
        assert np.allclose(rho(far, loss, 3.0), TUKEY_C**2 / 6)


def test_clipped_variance_share_matches_monte_carlo():
    rng = np.random.default_rng(0)
    for nu in (1, 3):
        x = chi2.rvs(nu, size=400_000, random_state=rng)
        assert _kappa(nu, 3.0) == pytest.approx(np.mean(np.minimum(x, 9.0)) / nu, abs=3e-3)


class _Obs:
    """The fields of an Observation that group_sigma reads, for hand-made residuals."""

    def __init__(self, pots, markers):
        self.pots, self.markers = pots, markers
        self.valid = np.isfinite(markers).all(axis=-1)
        self.kinds = np.array(["rotary"] * pots.shape[1], dtype=object)
        self.groups = ("rotary", "markers")


class _Params:
    def __init__(self, P, M):
        self.gain, self.bias = np.ones(P), np.zeros(P)
        self.xyz, self.R, self.T = np.zeros((M, 3)), np.eye(3), np.zeros(3)


class _State:
    def __init__(self, T, P, M):
        self.s, self.Rl, self.pl = np.zeros((T, P)), np.tile(np.eye(3), (T, M, 1, 1)), np.zeros((T, M, 3))


def test_robust_noise_level_is_consistent_and_bounded_under_outliers():
    """Gaussian residuals give σ back (fixed point of the clipped estimate); 5 % of gross errors
    move it by a bounded amount, where they multiply an RMS."""
    rng = np.random.default_rng(1)
    T, P, M = 4000, 3, 4
    sp, sx = 0.005, 0.002
    r_p = rng.normal(0, sp, (T, P))
    r_x = rng.normal(0, sx, (T, M, 3))
    obs, params, st = _Obs(-r_p, -r_x), _Params(P, M), _State(T, P, M)

    def fixed_point(o):
        s = {"rotary": 1.0, "markers": 1.0}
        for _ in range(200):
            s = group_sigma(o, params, st, None, s)
        return s

    s = fixed_point(obs)
    assert s["rotary"] == pytest.approx(sp, rel=0.03) and s["markers"] == pytest.approx(sx, rel=0.03)
    bad = rng.random((T, M)) < 0.05
    r_bad = r_x.copy()
    r_bad[bad] += rng.uniform(0.03, 0.15, (bad.sum(), 1)) * rng.choice([-1.0, 1.0], (bad.sum(), 3))
    s_bad = fixed_point(_Obs(-r_p, -r_bad))
    rms = np.sqrt(np.mean(r_bad[~np.isnan(r_bad[..., 0])] ** 2))
    assert sx < s_bad["markers"] < 1.3 * sx < 5 * sx < rms


# ----------------------------------------------------------------------------- STAC on corrupted mocap
@pytest.fixture(scope="module")
def finger_runs():
    """Finger, 500 frames: a label swap with the nearest marker (4.5 % of the frames) and ghost
    readings (2 % of every marker's samples), the same log without them, and the fits."""
    robot = load_robot(BUNDLED_ROBOTS / "finger")
    kw = dict(duration=25.0, rate_hz=20.0, occlusion=0.05)
    clean = simulate_kinematics(robot, KinematicsOptions(**kw), np.random.default_rng(11))
    effects = parse_effects(["swapped_labels:m3", "marker_outliers"])
    bad = simulate_kinematics(robot, KinematicsOptions(effects=effects, **kw), np.random.default_rng(11))
    corrupted = bad.truth.signals["markers_corrupted"].data
    assert 0.02 < corrupted.any(axis=1).mean() < 0.2  # a realistic share of the frames
    fits = {
        loss: calibrate(bad.without_truth(), robot, StacOptions(loss=loss)).calibration
        for loss in ("linear", "huber", "tukey")
    }
    fits["clean"] = calibrate(clean.without_truth(), robot, StacOptions()).calibration
    return robot, bad, fits


def _free(robot, log):
    """Estimated biases (not gauge-fixed) and markers not on a gauge joint's link (test_stac.py)."""
    obs = Observation(log, robot)
    obs.check_observable()
    return obs, ~obs.fixed_bias, obs.gauge_free_markers()


def _distance(cal, ref, bias_free, marker_free) -> float:
    """Largest |cal − ref| of the identifiable parameters, in the reference fit's standard errors."""
    return max(
        np.max(np.abs(cal.gain - ref.gain) / ref.gain_se),
        np.max((np.abs(cal.bias - ref.bias) / ref.bias_se)[bias_free]),
        np.max((np.abs(cal.marker_xyz - ref.marker_xyz) / ref.marker_xyz_se)[marker_free]),
    )


def test_tukey_recovers_the_truth_within_standard_errors(finger_runs):
    robot, log, fits = finger_runs
    cal, truth = fits["tukey"], Calibration.from_dict(log.truth.params)
    obs, bias_free, marker_free = _free(robot, log)
    # gauge-equivalent true biases: a fixed bias shifts its joint's zero, and the other pots on it
    b_equiv = obs.gauge_equivalent_bias(truth.gain, truth.bias, cal.bias)
    assert np.all(np.abs((cal.gain - truth.gain) / cal.gain_se) < Z)
    assert np.all(np.abs((cal.bias - b_equiv) / cal.bias_se)[bias_free] < Z)
    assert np.all(np.abs((cal.marker_xyz - truth.marker_xyz) / cal.marker_xyz_se)[marker_free] < Z)
    # its standard errors are the clean data's: σ is the noise, not the outliers
    assert cal.sigma_by_group["markers"] == pytest.approx(0.002, rel=0.15)
    assert cal.sigma_by_group["tendon"] == pytest.approx(0.005, rel=0.25)
    # and it lands where the fit to the clean log does, within two of that fit's standard errors
    assert _distance(cal, fits["clean"], bias_free, marker_free) < 2.0


def test_gaussian_fit_is_clearly_worse_and_huber_in_between(finger_runs):
    """loss='linear' ends many clean-data standard errors off with σ_x inflated several-fold;
    Huber on the markers keeps σ but its bounded (not zero) influence leaves a bias of a few
    standard errors that Tukey's biweight removes (robust.py)."""
    robot, log, fits = finger_runs
    _, bias_free, marker_free = _free(robot, log)
    d = {loss: _distance(fits[loss], fits["clean"], bias_free, marker_free) for loss in ("linear", "huber", "tukey")}
    assert d["linear"] > 2 * Z and fits["linear"].sigma_by_group["markers"] > 3 * 0.002
    assert d["tukey"] < d["huber"] < d["linear"] / 3
    assert fits["huber"].sigma_by_group["markers"] == pytest.approx(0.002, rel=0.15)
