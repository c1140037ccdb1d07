"""Timing of the robot observation models on diego (38 joints, 38 pots, 24 markers).

    .venv/bin/python bench/bench_robot.py [FRAMES]

Prints seconds and microseconds per frame for the per-frame Pinocchio loops behind
``predict_pots``/``predict_markers`` and their analytic Jacobians (thesis eq. 2.22-2.23), with the
reference methods timed in the same run: the same Jacobians by central finite differences
(2 n evaluations of the forward model), and the marker Jacobian by Pinocchio's per-point frame
Jacobians (``getFrameJacobian``, one call per point and frame: the implementation
``Robot.points_jacobian`` had before it was vectorised over points), with the largest difference.
"""

from __future__ import annotations

import sys
import time

import numpy as np
import pinocchio as pin

from diegocal.robot import (
    BUNDLED_ROBOTS,
    PointSet,
    load_robot,
    marker_points,
    markers_jacobian,
    pots_jacobian,
    predict_markers,
    predict_pots,
)


def timed(fn, repeats: int = 3) -> float:
    best = np.inf
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - start)
    return best


def finite_difference(f, q: np.ndarray, h: float = 1e-6) -> np.ndarray:
    T, n = q.shape
    steps = np.eye(n) * h
    plus = (q[:, None, :] + steps).reshape(T * n, n)
    minus = (q[:, None, :] - steps).reshape(T * n, n)
    return (f(plus) - f(minus)) / (2 * h)


def per_point_frame_jacobians(robot, q: np.ndarray, points: PointSet) -> np.ndarray:
    """Reference: ∂x/∂q (T, N, 3, n) in the base frame from one getFrameJacobian per point
    (LOCAL_WORLD_ALIGNED, J_v − [r]× J_ω); fixed base only."""
    model, data = robot.model, robot.model.createData()
    fids = [model.getFrameId(link) for link in points.links]
    lwa = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
    out = np.empty((len(q), len(fids), 3, robot.n_joints))
    for t in range(len(q)):
        pin.computeJointJacobians(model, data, q[t])
        pin.updateFramePlacements(model, data)
        Rb = data.oMf[robot.base_frame].rotation
        for k, fid in enumerate(fids):
            J6 = pin.getFrameJacobian(model, data, fid, lwa)
            r = data.oMf[fid].rotation @ points.xyz[k]
            skew = np.array([[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]])
            out[t, k] = Rb.T @ (J6[:3] - skew @ J6[3:])
    return out


def main(argv: list[str]) -> int:
    frames = int(argv[1]) if len(argv) > 1 else 500
    robot = load_robot(BUNDLED_ROBOTS / "diego")
    rng = np.random.default_rng(0)
    q = rng.uniform(robot.lower, robot.upper, size=(frames, robot.n_joints))
    gain = np.array([p.gain for p in robot.sensors.pots])
    bias = np.array([p.bias for p in robot.sensors.pots])
    xyz = np.array([m.xyz for m in robot.sensors.markers])
    R, T0 = np.eye(3), np.zeros(3)
    cases = [
        ("predict_pots", lambda: predict_pots(robot, q, gain, bias)),
        ("pots_jacobian (analytic)", lambda: pots_jacobian(robot, q, gain)),
        (
            "pots Jacobian (central FD, reference)",
            lambda: finite_difference(lambda x: predict_pots(robot, x, gain, bias), q),
        ),
        ("predict_markers", lambda: predict_markers(robot, q, xyz, R, T0)),
        ("markers_jacobian (analytic)", lambda: markers_jacobian(robot, q, xyz, R)),
        (
            "markers Jacobian (per-point Pinocchio, ref.)",
            lambda: per_point_frame_jacobians(robot, q, marker_points(robot)),
        ),
        (
            "markers Jacobian (central FD, reference)",
            lambda: finite_difference(lambda x: predict_markers(robot, x, xyz, R, T0), q),
        ),
    ]
    print(f"diego: {robot.n_joints} joints, {len(gain)} pots, {len(xyz)} markers, {frames} frames")
    print(f"{'method':<46} {'seconds':>9} {'us/frame':>10}")
    for name, fn in cases:
        seconds = timed(fn, repeats=1 if "FD" in name else 3)
        print(f"{name:<46} {seconds:>9.3f} {1e6 * seconds / frames:>10.1f}")
    _, fast = markers_jacobian(robot, q, xyz, R)
    slow = per_point_frame_jacobians(robot, q, marker_points(robot))
    diff = np.abs(fast - slow).max()
    print(f"largest |analytic - per-point reference| marker Jacobian entry: {diff:.1e} m/rad")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv))
