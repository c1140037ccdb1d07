"""Two routes agree: the structured J_θᵀ v of the Schur step equals the explicit Jacobian's, the
explicit J_θ equals finite differences of the standardised residuals, and the q-phase's normal
equations and redundancies, formed without the Jacobian, equal the dense Jacobian's products."""

import numpy as np
import pytest
import synth
from scipy.spatial.transform import Rotation

from diegocal.stac.joint_step import _dense_q_jacobian, _q_jacobian, _theta_jacobian, _theta_transpose_times
from diegocal.stac.model import Observation, Params
from diegocal.stac.qphase import Noise, normal_equations, residuals


def _setup(robot):
    log = synth.simulate(robot, 6, seed=3, occlusion=0.3)
    obs = Observation(log, robot)
    rng = np.random.default_rng(0)
    params = Params(
        obs.nominal().gain * 1.1,
        rng.normal(0, 0.1, obs.n_pots),
        rng.normal(0, 0.03, (obs.n_markers, 3)),
        Rotation.from_rotvec([0.2, -0.1, 0.3]).as_matrix(),
        np.array([0.1, 0.2, 0.3]),
    )
    noise = Noise(np.full(obs.n_pots, 0.01), 0.002)
    q = log.truth.signals["q"].data
    st = obs.state(q)
    return obs, params, noise, st


def _flat_residuals(obs, params, noise, st):
    zp, _, rx = residuals(obs, params, noise, st.s, st.Rl, st.pl, obs.pots, obs.markers, obs.valid)
    return np.concatenate([zp, rx.reshape(len(zp), -1)], axis=1)


def test_theta_jacobian_matches_finite_differences(tree_robot):
    obs, params, noise, st = _setup(tree_robot)
    J = _theta_jacobian(obs, params, noise, st.s, st.Rl, st.pl, obs.valid)
    P, M = obs.n_pots, obs.n_markers
    r0 = _flat_residuals(obs, params, noise, st)
    h = 1e-7
    for k in range(J.shape[-1]):
        d = np.zeros(J.shape[-1])
        d[k] = h
        p = Params(
            params.gain + d[:P],
            params.bias + d[P : 2 * P],
            params.xyz + d[2 * P : 2 * P + 3 * M].reshape(M, 3),
            Rotation.from_rotvec(d[-6:-3]).as_matrix() @ params.R,
            params.T + d[-3:],
        )
        fd = (_flat_residuals(obs, p, noise, st) - r0) / h
        np.testing.assert_allclose(J[..., k], fd, atol=2e-3 * max(1.0, np.abs(fd).max()))


def test_q_jacobian_from_the_linearisation_equals_the_forward_kinematics(tree_robot):
    """J_q from the kept twists (the reduced matrix's route) equals J_q from the kinematics."""
    obs, params, noise, _ = _setup(tree_robot)
    q = synth.simulate(tree_robot, 6, seed=3, occlusion=0.3).truth.signals["q"].data
    lin = obs.linearise(q)
    x = np.einsum("bmij,mj->bmi", lin.Rl, params.xyz) + lin.pl
    wp, wx = np.ones_like(obs.pots), obs.valid.astype(float)
    Jq, w = _q_jacobian(obs, params, noise, np.moveaxis(lin.xi, 0, 1), lin.ds_lin, x, wp, wx)
    Jd, wd = _dense_q_jacobian(obs, params, noise, q, wp, wx)
    np.testing.assert_allclose(Jq, Jd, rtol=1e-10, atol=1e-10 * np.abs(Jd).max())
    np.testing.assert_array_equal(w, wd)


def test_structured_transpose_product(tree_robot):
    obs, params, noise, st = _setup(tree_robot)
    J = _theta_jacobian(obs, params, noise, st.s, st.Rl, st.pl, obs.valid)
    v = np.random.default_rng(1).normal(size=J.shape[:2])
    v[:, obs.n_pots :] *= np.repeat(obs.valid, 3, axis=1)
    np.testing.assert_allclose(
        _theta_transpose_times(obs, params, noise, st.s, st.Rl, st.pl, v),
        np.einsum("bkn,bk->n", J, v),
        rtol=1e-10,
        atol=1e-8,
    )


def test_sparse_normal_equations_equal_the_dense_jacobian(tree_robot):
    """JᵀWJ, JᵀW r and tr(H⁻¹ H_g) per sensor type from the sparse route equal those of the dense
    eq. 2.22-2.23 Jacobian (Observation.evaluate), with occlusion and linear pots."""
    obs, params, noise, _ = _setup(tree_robot)
    q = np.random.default_rng(2).normal(0.0, 0.3, (obs.n_frames, tree_robot.n_joints))
    Hb, g, _, _, red, ex = normal_equations(obs, params, noise, q, slice(None), want_red=True)
    H = Hb.dense()  # (its blocks: obs.sparsity.blocks; zero between them, as the dense route says)
    _, ds, _, _, Jx = obs.evaluate(q, params.xyz)
    Jp = ds * (params.gain / noise.sig_p)[None, :, None]
    Jm = np.einsum("ij,bmjn->bmin", params.R, Jx) / noise.sig_x
    parts = {k: np.einsum("bpi,bpj->bij", Jp[:, obs.kinds == k], Jp[:, obs.kinds == k]) for k in ("rotary", "linear")}
    parts["markers"] = np.einsum("bmci,bm,bmcj->bij", Jm, ex["wx"], Jm)
    H_dense = sum(parts.values())
    np.testing.assert_allclose(H, H_dense, atol=1e-9 * np.abs(H_dense).max())
    g_dense = np.einsum("bpi,bp->bi", Jp, ex["zp"]) + np.einsum("bmci,bm,bmc->bi", Jm, ex["wx"], ex["rx"])
    np.testing.assert_allclose(g, g_dense, atol=1e-9 * np.abs(g_dense).max())
    n = H.shape[-1]
    eps = 1e-9 * (1.0 + np.einsum("bii->b", H_dense))
    Hi = np.linalg.inv(H_dense + eps[:, None, None] * np.eye(n))
    for k, Hk in parts.items():
        assert red[k] == pytest.approx(np.einsum("bij,bji->", Hi, Hk), rel=1e-9)
