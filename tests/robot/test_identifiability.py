"""Are the bundled robots calibratable? The Jacobian of every observation (pots, markers) with
respect to every unknown of STAC (thesis eq. 2.21: joint angles of each frame, pot gains and
biases, marker positions, mocap rotation and translation) has full column rank, up to one known
gauge freedom per joint of two kinds, each shifting the joint's zero and the biases of the pots
that read it:

* leaf gauge: every marker the joint moves sits on its own child link; rotating those markers
  about its axis (d -> Rot(a, -δ) d) absorbs the offset;
* root gauge: the joint hangs from the base (its axis is fixed in the base frame) and moves every
  marker; rotating the mocap frame about its axis (R, T) absorbs the offset.

Fixing one rotary pot's bias per gauge joint removes it, and nothing else is lost. The thesis
does not discuss these gauges; the STAC code must fix them (or compare biases modulo them).
"""

from __future__ import annotations

import numpy as np
import pytest
from threadpoolctl import threadpool_limits

from diegocal.robot import markers_jacobian, pots_jacobian

EXPECTED_GAUGES = {
    "diego": {"head_pitch", "r_wrist_roll", "l_wrist_roll", "r_toe", "l_toe"},
    "finger": {"dip", "mcp_abd"},
}


def gauge_joints(robot) -> list[int]:
    """Indices of the leaf-gauge and root-gauge joints (module docstring); fixed base only."""
    model = robot.model
    assert robot._base_is_fixed()
    marker_joint = [model.frames[robot.frame_id(m.link)].parentJoint for m in robot.sensors.markers]
    out = []
    for k in range(1, model.njoints):
        moved = [j for j in marker_joint if k in list(model.supports[j])]
        leaf = moved and all(j == k for j in moved)
        root = model.parents[k] == 0 and len(moved) == len(marker_joint)
        if leaf or root:
            out.append(k - 1)
    return out


def _skew(v):
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def calibration_jacobian(robot, q: np.ndarray) -> tuple[np.ndarray, dict]:
    """∂(pots, markers)/∂(q_1..q_T, gain, bias, marker xyz, mocap rotation, mocap translation).

    Rows: T·P pot readings then T·M·3 marker coordinates; mocap frame at the identity.
    """
    pots, markers = robot.sensors.pots, robot.sensors.markers
    T, n, P, M = len(q), robot.n_joints, len(pots), len(markers)
    gain = np.array([p.gain for p in pots])
    xyz = np.array([m.xyz for m in markers])
    s, dp = pots_jacobian(robot, q, gain)
    xb, dx = markers_jacobian(robot, q, xyz, np.eye(3))
    link_R, _ = robot.link_poses(q, [m.link for m in markers])
    col = {"gain": T * n, "bias": T * n + P, "xyz": T * n + 2 * P, "rot": T * n + 2 * P + 3 * M}
    col["trans"] = col["rot"] + 3
    J = np.zeros((T * (P + 3 * M), col["trans"] + 3))
    for t in range(T):
        rp = slice(t * P, (t + 1) * P)
        J[rp, t * n : (t + 1) * n] = dp[t]
        J[rp, col["gain"] : col["gain"] + P] = np.diag(s[t])
        J[rp, col["bias"] : col["bias"] + P] = np.eye(P)
        r0 = T * P + t * 3 * M
        J[r0 : r0 + 3 * M, t * n : (t + 1) * n] = dx[t].reshape(3 * M, n)
        for m in range(M):
            rm = slice(r0 + 3 * m, r0 + 3 * m + 3)
            J[rm, col["xyz"] + 3 * m : col["xyz"] + 3 * m + 3] = link_R[t, m]
            J[rm, col["rot"] : col["rot"] + 3] = -_skew(xb[t, m])
            J[rm, col["trans"] : col["trans"] + 3] = np.eye(3)
    return J, col


def normalised_singular_values(J: np.ndarray) -> np.ndarray:
    """Singular values of J with unit-norm columns (units differ: rad, V/rad, V, m)."""
    # one BLAS thread: a small SVD on a shared, loaded machine is 50x slower with many
    with threadpool_limits(1):
        return np.linalg.svd(J / np.linalg.norm(J, axis=0), compute_uv=False)


@pytest.mark.parametrize("name", ["diego", "finger"])
def test_calibration_identifiable_up_to_gauges(name, bundled, sample_q):
    robot = bundled(name)
    gauges = gauge_joints(robot)
    assert {robot.joint_names[k] for k in gauges} == EXPECTED_GAUGES[name]
    # each gauge joint is read by a rotary pot, whose bias is the one to fix
    fixed = []
    for k in gauges:
        readers = [
            i
            for i, p in enumerate(robot.sensors.pots)
            if p.kind == "rotary" and p.joint == robot.joint_names[k]
        ]
        assert readers, robot.joint_names[k]
        fixed.append(readers[0])

    q = sample_q(robot, np.random.default_rng(5), 6)
    J, col = calibration_jacobian(robot, q)
    free = normalised_singular_values(J)
    # with every bias free the Jacobian loses exactly one direction per gauge joint ...
    assert (free < 1e-9).sum() == len(gauges)
    # ... and fixing those biases leaves every other unknown identifiable (tendon and linear
    # pots' gains and biases included)
    keep = np.setdiff1d(np.arange(J.shape[1]), col["bias"] + np.array(fixed))
    fixed_sv = normalised_singular_values(J[:, keep])
    assert fixed_sv.min() > 1e-5


def test_gauge_is_the_leaf_rotation(bundled, sample_q):
    """The null direction for dip is as described: δq_dip with the dip pot's bias shift and the
    distal markers rotated by −δ about the dip axis (a direct check of the analysis)."""
    robot = bundled("finger")
    q = sample_q(robot, np.random.default_rng(6), 6)
    J, col = calibration_jacobian(robot, q)
    k = robot.joint_index("dip")
    n, T = robot.n_joints, len(q)
    direction = np.zeros(J.shape[1])
    direction[[t * n + k for t in range(T)]] = 1.0
    for i, p in enumerate(robot.sensors.pots):
        r = p.moment_arms.get("dip", 0.0) if p.kind == "tendon" else float(p.joint == "dip")
        direction[col["bias"] + i] = -p.gain * r
    axis = np.array([0.0, 1.0, 0.0])  # dip axis in the distal frame (make_robots: flexion about y)
    for m, marker in enumerate(robot.sensors.markers):
        if marker.link == "distal":
            direction[col["xyz"] + 3 * m : col["xyz"] + 3 * m + 3] = -np.cross(axis, marker.xyz)
    assert np.abs(J @ direction).max() < 1e-10
    assert np.abs(direction).max() > 0.1
