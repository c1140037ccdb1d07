"""The guard's "extended" candidate: where ML-II presses a length-scale against the cap, the
likelihood chooses the limit (a constant along an irrelevant input, a linear trend along a
velocity), so a viscous friction the parametric model omits is extrapolated, not dropped.

Ground truth from a known function: y = w·f(u) + d(u) with d a viscous friction, linear in the
velocity, on output 0 and nothing on output 1; the test's velocities lie 2-4 training stds
outside the training range (a reaction wheel spun faster than in training).
"""

from dataclasses import replace

import numpy as np
import pytest

from diegocal.sgp import DEFAULT_GUARD, SemiParametricGP, SquaredExponential

W_TRUE = np.array([1.5, -0.7])
VISCOUS = -2.0  # output 0's deviation: VISCOUS × velocity


def _data(rng, N, velocity_range, deviation):
    angle = rng.uniform(-1.0, 1.0, N)
    velocity = rng.uniform(*velocity_range, N)
    U = np.column_stack([angle, velocity])
    F = np.zeros((N, 2, 2))
    F[:, :, 0] = np.sin(angle)[:, None]
    F[:, :, 1] = rng.uniform(-1.0, 1.0, N)[:, None]  # a command both outputs are linear in
    clean = F @ W_TRUE
    clean[:, 0] += deviation(velocity)
    return U, clean + 0.02 * rng.standard_normal(clean.shape), F, clean


def _fit(U, Y, F, extend: bool):
    kernels = [SquaredExponential(2) for _ in range(2)]
    guard = replace(DEFAULT_GUARD, extend_capped=extend)
    return SemiParametricGP(kernels, guard=guard, restarts=1, seed=0).fit(U, Y, F)


def _nmse(est, test):
    U, _, F, clean = test
    mean, _, _ = est.predict(U, F)
    return np.mean((mean - clean) ** 2, axis=0) / np.var(clean, axis=0)


@pytest.fixture(scope="module")
def viscous():
    rng = np.random.default_rng(5)

    def friction(v):
        return VISCOUS * v

    U, Y, F, _ = _data(rng, 240, (-1.0, 1.0), friction)
    test = _data(rng, 200, (1.5, 3.0), friction)  # faster than any training sample
    return {e: _fit(U, Y, F, e) for e in (True, False)}, test


def test_a_viscous_friction_is_extrapolated_linearly(viscous):
    fits, test = viscous
    ext, capped = _nmse(fits[True], test), _nmse(fits[False], test)
    assert fits[True].selection_[0] == "extended", fits[True].validation_scores_
    assert ext[0] < 0.2 * capped[0], (ext, capped)
    np.testing.assert_allclose(fits[True].w_, W_TRUE, atol=0.05)


def test_a_local_deviation_keeps_its_short_length_scale():
    """A bump in the velocity (width 0.15) is no ridge: the likelihood refuses to stretch it."""
    rng = np.random.default_rng(6)

    def bump(v):
        return 1.0 * np.exp(-0.5 * ((v - 0.3) / 0.15) ** 2)

    U, Y, F, _ = _data(rng, 240, (-1.0, 1.0), bump)
    est = _fit(U, Y, F, True)
    velocity_scale = np.exp(est.hyper_.theta[0][2])  # [log σ_z, log ℓ_angle, log ℓ_velocity]
    assert est.selection_[0] != "parametric"
    assert velocity_scale < 1.0, est.hyper_.theta[0]


def test_inputs_the_features_are_linear_in_are_found_exactly():
    """The stretch releases inputs in which the parametric part is exactly linear (W's own
    column): found per output through the kernels' input columns, a near-linear one (sin of a
    small angle) is not."""
    from diegocal.sgp import Subspace
    from diegocal.sgp.kernels import Constant

    rng = np.random.default_rng(7)
    angle, drift, velocity = rng.uniform(-0.3, 0.3, 50), rng.uniform(-5, 5, 50), rng.uniform(-1, 1, 50)
    U = np.column_stack([angle, drift, velocity])
    F = np.zeros((50, 2, 3))
    F[:, 0] = np.column_stack([np.sin(angle), drift, np.zeros(50)])  # output 0: linear in the drift
    F[:, 1] = np.column_stack([np.sin(angle), np.zeros(50), 2.0 * velocity - 1.0])  # output 1: velocity
    kernels = [Subspace((0, 1, 2), SquaredExponential(3)), Subspace((2, 1), SquaredExponential(2)) + Constant()]
    assert kernels[1].lengthscale_inputs == (None, 2, 1, None)
    est = SemiParametricGP(kernels)
    est.u_mean_, est.u_std_, est.f_scale_ = U.mean(0), U.std(0), np.ones(3)
    Us, Fs = est._scale(U, F)
    # packed: [σ_w, σ_v0, σ_v1, (σ_z, ℓ0, ℓ1, ℓ2) of output 0, (σ_z, ℓ2, ℓ1, c) of output 1]
    assert est._linear_slots(Us, Fs) == {3 + 2, 7 + 1}
