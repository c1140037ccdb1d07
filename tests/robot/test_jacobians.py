"""Analytic Jacobians of every sensor kind equal central finite differences (thesis eq. 2.22-2.23).

Random configurations within the joint limits of diego, finger and a tiny robot whose base link
is not the URDF root (the moving-base branch of ``Robot.points_jacobian``), with an encoder on a
prismatic joint.
"""

from __future__ import annotations

import sys

import numpy as np
import pytest

from diegocal.robot import (
    PointSet,
    markers_jacobian,
    pots_jacobian,
    predict_markers,
    predict_pots,
)

H = 1e-6  # finite-difference step, rad or m


def central_difference(f, q: np.ndarray) -> np.ndarray:
    """∂f/∂q by central differences for vectorised f: (T, n) -> (T, ...); returns (T, ..., n)."""
    T, n = q.shape
    steps = np.eye(n) * H
    plus = (q[:, None, :] + steps[None]).reshape(T * n, n)
    minus = (q[:, None, :] - steps[None]).reshape(T * n, n)
    diff = (f(plus) - f(minus)) / (2 * H)  # (T * n, ...)
    diff = diff.reshape(T, n, *diff.shape[1:])
    return np.moveaxis(diff, 1, -1)


def robot_by_name(name, bundled, tiny_robot):
    return tiny_robot if name == "tiny" else bundled(name)


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


@pytest.mark.parametrize(
    ("robot_name", "kind"),
    [
        ("diego", "rotary"),
        ("diego", "linear"),
        ("finger", "tendon"),
        ("finger", "rotary"),
        ("tiny", "encoder"),
        ("tiny", "rotary"),
        ("tiny", "tendon"),
        ("tiny", "linear"),
    ],
)
def test_pot_jacobian_matches_finite_differences(robot_name, kind, bundled, tiny_robot, sample_q):
    robot = robot_by_name(robot_name, bundled, tiny_robot)
    rows = [i for i, p in enumerate(robot.sensors.pots) if p.kind == kind]
    assert rows, f"{robot_name} has no {kind} sensor: the test would be vacuous"
    gain = np.array([p.gain for p in robot.sensors.pots])
    bias = np.array([p.bias for p in robot.sensors.pots])
    q = sample_q(robot, np.random.default_rng(11), 4)

    s, jac = pots_jacobian(robot, q, gain)
    numeric = central_difference(lambda x: predict_pots(robot, x, gain, bias), q)

    np.testing.assert_allclose(s * gain + bias, predict_pots(robot, q, gain, bias), atol=1e-12)
    assert np.abs(jac[:, rows]).max() > 1e-3  # the sensors do move
    np.testing.assert_allclose(jac[:, rows], numeric[:, rows], rtol=1e-6, atol=1e-7)


@pytest.mark.parametrize("robot_name", ["diego", "finger", "tiny"])
def test_marker_jacobian_matches_finite_differences(robot_name, bundled, tiny_robot, sample_q):
    robot = robot_by_name(robot_name, bundled, tiny_robot)
    rng = np.random.default_rng(12)
    xyz = np.array([m.xyz for m in robot.sensors.markers]) + rng.normal(
        0, 0.01, (len(robot.sensors.markers), 3)
    )
    mocap_R, mocap_T = random_rotation(rng), rng.normal(0, 1.0, 3)
    q = sample_q(robot, rng, 4)

    xb, jac = markers_jacobian(robot, q, xyz, mocap_R)
    numeric = central_difference(lambda x: predict_markers(robot, x, xyz, mocap_R, mocap_T), q)

    np.testing.assert_allclose(
        xb @ mocap_R.T + mocap_T, predict_markers(robot, q, xyz, mocap_R, mocap_T), atol=1e-12
    )
    assert np.abs(jac).max() > 1e-2
    np.testing.assert_allclose(jac, numeric, rtol=1e-6, atol=1e-7)


def test_moving_base_points_jacobian(tiny_robot, sample_q):
    """Base link below the root: joints upstream of the base move nothing in the base frame,
    the prismatic joint between l0 and the base moves l0's points, and both routes agree."""
    robot = tiny_robot
    assert not robot._base_is_fixed()
    xyz = [
        [0.03, 0.02, 0.01],
        [0.1, -0.2, 0.3],
        [0.01, 0.02, 0.03],
        [0.1, 0.0, 0.02],
        [0.04, -0.02, 0.01],
    ]
    points = PointSet(("l0", "world_link", "base", "arm", "hand"), np.array(xyz))
    q = sample_q(robot, np.random.default_rng(13), 5)

    x, jac = robot.points_jacobian(q, points)
    numeric = central_difference(lambda z: robot.points(z, points), q)

    np.testing.assert_allclose(x, robot.points(q, points), atol=1e-12)
    np.testing.assert_allclose(jac, numeric, rtol=1e-6, atol=1e-7)
    j0, slide = robot.joint_index("j0"), robot.joint_index("slide")
    downstream_of_j0 = [0, 2, 3, 4]  # every link but the root turns with the base under j0
    np.testing.assert_allclose(jac[:, downstream_of_j0, :, j0], 0.0, atol=1e-12)
    np.testing.assert_allclose(jac[:, 2], 0.0, atol=1e-12)  # a point on the base itself
    assert np.linalg.norm(jac[:, 0, :, slide], axis=-1).min() > 0.5  # m/m: l0 slides past the base
    # the world frame moves relative to the base under j0 as well
    assert np.linalg.norm(jac[:, 1, :, j0], axis=-1).min() > 1e-2


def test_point_and_q_shapes_are_checked(tiny_robot):
    q = tiny_robot.neutral()
    with pytest.raises(ValueError, match=r"expected \(3, 3\), got \(2, 3\)"):
        tiny_robot.points(q, PointSet(("l0", "arm", "hand"), np.zeros((2, 3))))
    with pytest.raises(ValueError, match=r"expected shape \(T, 4\), got \(1, 3\)"):
        tiny_robot.points_jacobian(q[:3], PointSet(("arm",), np.zeros((1, 3))))
    with pytest.raises(ValueError, match="expected"):
        predict_markers(tiny_robot, q, np.zeros((2, 3)), np.eye(3), np.zeros(3))


def test_kinematics_is_thread_safe(bundled, sample_q):
    """Concurrent calls on one Robot (``--jobs`` with threads) give the sequential results."""
    from concurrent.futures import ThreadPoolExecutor

    robot = bundled("diego")
    points = PointSet(
        tuple(m.link for m in robot.sensors.markers),
        np.array([m.xyz for m in robot.sensors.markers]),
    )
    batches = [sample_q(robot, np.random.default_rng(20 + i), 30) for i in range(12)]
    expected = [robot.points_jacobian(q, points) for q in batches]
    interval = sys.getswitchinterval()
    sys.setswitchinterval(1e-6)  # switch threads often, so shared state would show
    try:
        with ThreadPoolExecutor(max_workers=4) as pool:
            got = list(pool.map(lambda q: robot.points_jacobian(q, points), batches))
    finally:
        sys.setswitchinterval(interval)
    for (x0, j0), (x1, j1) in zip(expected, got, strict=True):
        np.testing.assert_array_equal(x0, x1)
        np.testing.assert_array_equal(j0, j1)
