"""The guard's blocked cross-validation chooses, output by output, between the capped
hyperparameters, the ones with the capped inputs released, and the parametric model alone.

Ground truth from a known function: y = w·f(u) + d(u), where the deviation d is a friction of the
velocity on one output and absent on the other; a third input, irrelevant, drifts (a wheel angle):
in the test it is far outside its training range while the velocity stays inside.
"""

from dataclasses import replace

import numpy as np
import pytest

from diegocal.sgp import DEFAULT_GUARD, SemiParametricGP, SquaredExponential

W_TRUE = np.array([1.5, -0.7])
FRICTION = -2.0  # the deviation on output 0: FRICTION × tanh(velocity / 0.3) (Coulomb-like)


def _data(rng, N, velocity_range, drift_range):
    angle = rng.uniform(-1.0, 1.0, N)
    velocity = rng.uniform(*velocity_range, N)
    drift = np.sort(rng.uniform(*drift_range, N))  # an irrelevant input that drifts (a wheel angle)
    U = np.column_stack([angle, velocity, drift])
    F = np.zeros((N, 2, 2))
    F[:, :, 0] = np.sin(angle)[:, None]
    F[:, :, 1] = rng.uniform(-1.0, 1.0, N)[:, None]  # a command both outputs are linear in
    clean = F @ W_TRUE
    clean[:, 0] += FRICTION * np.tanh(velocity / 0.3)
    return U, clean + 0.02 * rng.standard_normal(clean.shape), F, clean


@pytest.fixture(scope="module")
def fits():
    rng = np.random.default_rng(3)
    U, Y, F, _ = _data(rng, 240, (-1.0, 1.0), (0.0, 1.0))
    # test: velocities in the training range, the drifting input far beyond it
    test = _data(rng, 200, (-1.0, 1.0), (3.0, 6.0))
    guard = replace(DEFAULT_GUARD, release_capped=True, two_stage=False)  # the release alone
    out = {}
    for label, g in (("with", guard), ("without", replace(guard, release_capped=False, extend_capped=False))):
        kernels = [SquaredExponential(3) for _ in range(2)]
        out[label] = SemiParametricGP(kernels, guard=g, restarts=1, seed=0).fit(U, Y, F)
    return out, test


def _nmse(est, test):
    U, _, F, clean = test
    mean, _, _ = est.predict(U, F)
    return np.mean((mean - clean) ** 2, axis=0) / np.var(clean, axis=0)


def test_the_irrelevant_drifting_input_is_released_and_the_friction_kept(fits):
    est, capped = fits[0]["with"], fits[0]["without"]
    assert est.selection_[0] == "released", est.validation_scores_
    assert capped.selection_[0] == "learnt"
    e_est, e_capped = _nmse(est, fits[1]), _nmse(capped, fits[1])
    assert e_est[0] < 0.5 * e_capped[0], (e_est, e_capped)


def test_an_output_without_deviation_predicts_like_the_true_parametric_model(fits):
    """Whichever the validation keeps there (the GP or not: equal within the noise), the output
    with nothing to model extrapolates like the true model, and W is the truth."""
    est = fits[0]["with"]
    assert est.selection_[1] in ("learnt", "released", "parametric")
    np.testing.assert_allclose(est.w_, W_TRUE, atol=0.05)
    assert _nmse(est, fits[1])[1] < 2e-3


def test_the_parametric_fallback_is_pr():
    """The fallback the cross-validation offers is PR itself: σ_w and σ_v learnt by ML-II without
    GP (σ_w's shrinkage holds W's weakly excited directions), so an output falling back predicts
    like PR, not like an unregularised least-squares fit."""
    from diegocal.sgp.gp import Hyperparameters

    rng = np.random.default_rng(4)
    U, Y, F, _ = _data(rng, 120, (-1.0, 1.0), (0.0, 1.0))
    est = SemiParametricGP([SquaredExponential(3) for _ in range(2)], guard=DEFAULT_GUARD, seed=0).fit(U, Y, F)
    pr = SemiParametricGP([None, None]).fit(U, Y, F)
    Us, Fs = est._scale(U, F)
    hp0, resid = est._initial(Us, Y, Fs)
    vec = est._parametric_only(hp0.pack(), resid, est._bounds(hp0, resid), (Us, Y, Fs))
    assert vec[0] == pytest.approx(pr.hyper_.log_sigma_w, abs=1e-3)
    np.testing.assert_allclose(vec[1:3], pr.hyper_.log_sigma_v, atol=1e-3)
    fallback = est.fit(U, Y, F, hyperparameters=Hyperparameters.unpack(vec, [4, 4]))
    np.testing.assert_allclose(fallback.w_, pr.w_, rtol=1e-4)
    np.testing.assert_allclose(fallback.predict(U, F)[0], pr.predict(U, F)[0], rtol=1e-4, atol=1e-6)


def test_a_gp_must_beat_the_fallback_by_one_standard_error():
    """choose_by_validation: options (learnt, released, parametric) × 5 blocks × 3 outputs."""
    from diegocal.sgp.estimator import choose_by_validation

    pr = np.array([1.0, 1.2, 0.9, 1.1, 1.0])
    per_block = np.stack(
        [
            np.column_stack([pr - 0.30, pr - 0.01 * np.array([1, -1, 1, -1, 1]), pr + 0.1]),  # learnt
            np.column_stack([pr - 0.20, pr + 0.05, pr + 0.2]),  # released
            np.column_stack([pr, pr, pr]),  # parametric
        ]
    )
    # output 0: learnt wins clearly; output 1: learnt lower on average by less than one SE of
    # the paired difference -> PR; output 2: PR is best anyway
    assert choose_by_validation(per_block, fallback=2).tolist() == [0, 2, 2]
    per_block[0, :, 1] = pr - 0.05  # a consistent gain, far beyond its (zero) spread
    assert choose_by_validation(per_block, fallback=2).tolist() == [0, 0, 2]
