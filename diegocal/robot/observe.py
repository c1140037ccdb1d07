"""Observation models of every sensor kind and their Jacobians with respect to q (thesis §2.3).

All functions are vectorised over frames: ``q`` is (T, n); outputs put frames first.

Pots (eq. 2.18-2.20) share one form, linear in their parameters:

.. math:: \\hat p_j(\\theta, q) = \\theta_{gain,j} \\, s_j(q) + \\theta_{bias,j}

with the transmission quantity :math:`s_j` = the joint angle (rotary; encoder with gain 1),
the anchor-to-anchor length :math:`L_j(q)` (linear pots on gimbals, eq. 2.19-2.20) or
:math:`\\sum_i r_{ji} q_i` (tendons spanning joints, moment arms r in metres, §2.3.3).

Markers (eq. 2.11-2.12): :math:`\\hat x_m = R (h_r(q) d_m + h_p(q)) + T_0`.
"""

from __future__ import annotations

import numpy as np

from diegocal.robot.model import PointSet, Robot


def anchor_points(robot: Robot) -> PointSet:
    """Both anchors of every linear pot, in pot order: (2 · n_linear,) points."""
    links, xyz = [], []
    for p in robot.sensors.pots:
        if p.kind == "linear":
            for a in p.anchors:
                links.append(a.link)
                xyz.append(a.xyz)
    return PointSet(tuple(links), np.array(xyz, dtype=float).reshape(-1, 3))


def marker_points(robot: Robot, xyz=None) -> PointSet:
    """The robot's markers as a point set; ``xyz`` (M, 3) overrides the nominal positions."""
    markers = robot.sensors.markers
    xyz = (
        np.array([m.xyz for m in markers], dtype=float).reshape(-1, 3)
        if xyz is None
        else np.asarray(xyz, float)
    )
    return PointSet(tuple(m.link for m in markers), xyz)


def _linear_map(robot: Robot) -> np.ndarray:
    """(P, n) matrix A with s(q) = A q for rotary, encoder and tendon pots (linear pots: 0 rows)."""
    A = np.zeros((len(robot.sensors.pots), robot.n_joints))
    for i, p in enumerate(robot.sensors.pots):
        if p.kind in ("rotary", "encoder"):
            A[i, robot.joint_index(p.joint)] = 1.0
        elif p.kind == "tendon":
            for joint, arm in p.moment_arms.items():
                A[i, robot.joint_index(joint)] = arm
    return A


def pot_transmission(robot: Robot, q) -> np.ndarray:
    """The transmission quantity s(q) of every pot: (T, P), rad or m."""
    q = robot.check_q(q)
    s = q @ _linear_map(robot).T
    linear = [i for i, p in enumerate(robot.sensors.pots) if p.kind == "linear"]
    if linear:
        x = robot.points(q, anchor_points(robot))
        s[:, linear] = np.linalg.norm(x[:, 1::2] - x[:, 0::2], axis=-1)  # eq. 2.19-2.20: L(q)
    return s


def pot_transmission_jacobian(robot: Robot, q) -> tuple[np.ndarray, np.ndarray]:
    """s(q) (T, P) and ∂s/∂q (T, P, n); for linear pots ∂L/∂q = uᵀ (J_b − J_a), u the unit axis."""
    q = robot.check_q(q)
    A = _linear_map(robot)
    s = q @ A.T
    jac = np.broadcast_to(A, (q.shape[0], *A.shape)).copy()
    linear = [i for i, p in enumerate(robot.sensors.pots) if p.kind == "linear"]
    if linear:
        x, J = robot.points_jacobian(q, anchor_points(robot))
        d = x[:, 1::2] - x[:, 0::2]
        length = np.linalg.norm(d, axis=-1)
        u = d / length[..., None]
        s[:, linear] = length
        jac[:, linear] = np.einsum("tkc,tkcn->tkn", u, J[:, 1::2] - J[:, 0::2])
    return s, jac


def predict_pots(robot: Robot, q, gain, bias) -> np.ndarray:
    """Pot readings (T, P), eq. 2.18-2.20; ``gain``, ``bias`` (P,) in pot order."""
    return pot_transmission(robot, q) * np.asarray(gain) + np.asarray(bias)


def pots_jacobian(robot: Robot, q, gain) -> tuple[np.ndarray, np.ndarray]:
    """s(q) (T, P) and ∂p̂/∂q = gain · ∂s/∂q (T, P, n), thesis eq. 2.22."""
    s, ds = pot_transmission_jacobian(robot, q)
    return s, ds * np.asarray(gain)[None, :, None]


def predict_markers(robot: Robot, q, xyz, mocap_R, mocap_T) -> np.ndarray:
    """Marker positions in the mocap frame (T, M, 3), eq. 2.11-2.12.

    Parameters
    ----------
    xyz : (M, 3) marker positions d_m in their link frames, m
    mocap_R : (3, 3) rotation R from base link to mocap frame
    mocap_T : (3,) translation T_0, m
    """
    xb = robot.points(q, marker_points(robot, xyz))
    return xb @ np.asarray(mocap_R).T + np.asarray(mocap_T)


def markers_jacobian(robot: Robot, q, xyz, mocap_R) -> tuple[np.ndarray, np.ndarray]:
    """Marker positions in the base frame (T, M, 3), m, and ∂x̂/∂q in the mocap frame (T, M, 3, n),
    m/rad; thesis eq. (2.23)."""
    xb, J = robot.points_jacobian(q, marker_points(robot, xyz))
    return xb, np.einsum("ij,tmjn->tmin", np.asarray(mocap_R), J)
