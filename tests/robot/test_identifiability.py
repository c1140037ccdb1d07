"""Are the robots calibratable? The Jacobian of every observation (pots, markers) with respect
to every unknown of STAC (thesis eq. 2.21: joint angles of each frame, pot gains and biases,
marker positions, mocap rotation and translation) has full column rank, up to exactly the gauge
freedoms :func:`diegocal.robot.gauge_joints` names (leaf and root gauges, see its module). Fixing
one bias per gauge joint removes them, and nothing else is lost.
"""

from __future__ import annotations

import numpy as np
import pytest
from threadpoolctl import threadpool_limits

from diegocal.robot import gauge_joints, load_robot, markers_jacobian, pots_jacobian

EXPECTED_GAUGES = {
    "diego": {"head_pitch", "r_wrist_roll", "l_wrist_roll", "r_toe", "l_toe"},  # leaves
    "finger": {"dip", "mcp_abd"},  # leaf, root
    "tiny": set(),  # its linear pots span slide and j3, which breaks their gauges
    # without them: slide is upstream of the base and moves only the l0 marker (leaf, far side)
    "tiny_no_linear": {"slide", "j3"},
}


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


def bias_to_fix(robot, joint: str) -> int:
    """A pot reading ``joint`` whose bias removes its gauge: rotary/encoder first, else tendon."""
    readers = [i for i, p in enumerate(robot.sensors.pots) if joint in p.joints]
    readers.sort(key=lambda i: robot.sensors.pots[i].kind == "tendon")
    assert readers, joint
    return readers[0]


@pytest.mark.parametrize("name", ["diego", "finger", "tiny", "tiny_no_linear"])
def test_calibration_identifiable_up_to_gauges(
    name, bundled, tiny_robot, sample_q, robot_dir, tiny_sensors
):
    if name == "tiny_no_linear":
        tiny_sensors["pots"] = [p for p in tiny_sensors["pots"] if p["kind"] != "linear"]
        robot = load_robot(robot_dir(tiny_sensors))
    else:
        robot = tiny_robot if name == "tiny" else bundled(name)
    gauges = gauge_joints(robot)
    assert set(gauges) == EXPECTED_GAUGES[name]
    fixed = [bias_to_fix(robot, joint) for joint in gauges]
    if "tiny" not in name:  # the bundled robots have a rotary pot on every gauge joint
        assert all(robot.sensors.pots[i].kind == "rotary" for i in fixed)

    q = sample_q(robot, np.random.default_rng(5), 6)
    J, col = calibration_jacobian(robot, q)
    # a joint upstream of the base that no pot reads moves nothing relative to the base (tiny's j0):
    # its angle is not a calibration unknown at all (load_robot locks it unless the data use it,
    # as tiny_robot's do; tiny_no_linear's do not)
    assert ("j0" in robot.locked) == (name == "tiny_no_linear")
    inert = np.flatnonzero(np.linalg.norm(J, axis=0) == 0)
    expected_inert = [t * robot.n_joints + robot.joint_index("j0") for t in range(6)] if name == "tiny" else []
    np.testing.assert_array_equal(inert, expected_inert)
    J = np.delete(J, inert, axis=1)
    col = {key: c - len(inert) for key, c in col.items()}
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


@pytest.mark.parametrize("name", ["diego", "finger"])
def test_gauge_axes_give_each_leaf_gauges_null_direction(name, bundled, sample_q):
    """:func:`gauge_axes`' axis is the one the leaf gauge turns its markers about: δq_k with its
    pots' bias shifts and those markers turned by −δ about that axis (through the joint's origin,
    in their link frame) changes no observation, for every revolute leaf gauge of the robot."""
    from diegocal.robot.gauges import gauge_axes

    robot = bundled(name)
    q = sample_q(robot, np.random.default_rng(7), 5)
    J, col = calibration_jacobian(robot, q)
    n, T = robot.n_joints, len(q)
    bound = gauge_axes(robot, gauge_joints(robot))
    assert {joint for joint, _ in bound.values()} == EXPECTED_GAUGES[name] - {"mcp_abd"}  # mcp_abd: a root gauge
    for joint in {joint for joint, _ in bound.values()}:
        k = robot.joint_index(joint)
        direction = np.zeros(J.shape[1])
        direction[[t * n + k for t in range(T)]] = 1.0
        for i, p in enumerate(robot.sensors.pots):
            r = p.moment_arms.get(joint, 0.0) if p.kind == "tendon" else float(p.joint == joint)
            direction[col["bias"] + i] = -p.gain * r
        for m, marker in enumerate(robot.sensors.markers):
            if bound.get(marker.name, ("",))[0] == joint:
                place = robot.model.frames[robot.frame_id(marker.link)].placement
                origin = -place.rotation.T @ place.translation  # the joint's origin in the link frame
                axis = bound[marker.name][1]
                direction[col["xyz"] + 3 * m : col["xyz"] + 3 * m + 3] = -np.cross(axis, marker.xyz - origin)
        assert np.abs(J @ direction).max() < 1e-9, joint
