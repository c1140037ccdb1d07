"""The robust losses and noise level of :mod:`diegocal.stac.robust`."""

import numpy as np
import pytest
from scipy.stats import chi2

from diegocal.stac.robust import TUKEY_C, _kappa, group_sigma, rho, weight


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
