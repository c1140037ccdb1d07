"""Two routes agree: vectorised kinematics equals Robot.points / points_jacobian (Pinocchio)."""

import numpy as np
import pytest
import synth

from diegocal.io import load_yaml, save_yaml
from diegocal.robot import anchor_points, load_robot, marker_points
from diegocal.robot.batch import BatchKinematics


def _check(robot, seed):
    rng = np.random.default_rng(seed)
    q = synth.smooth_q(robot, 7, 1.0, rng) + rng.normal(0, 0.3, (7, robot.n_joints))
    kin = BatchKinematics(robot)
    poses = kin.joint_poses(q)
    for pts in (marker_points(robot), anchor_points(robot)):
        if not pts.links:
            continue
        x_ref, J_ref = robot.points_jacobian(q, pts)
        x, J = kin.points_jacobian(poses, pts)
        np.testing.assert_allclose(x, robot.points(q, pts), atol=1e-12)
        np.testing.assert_allclose(x, x_ref, atol=1e-12)
        np.testing.assert_allclose(J, J_ref, atol=1e-12)
    links = list(robot.sensors.marker_names and [m.link for m in robot.sensors.markers])
    R_ref, p_ref = robot.link_poses(q, links)
    R, p = kin.link_poses(poses, links)
    np.testing.assert_allclose(R, R_ref, atol=1e-12)
    np.testing.assert_allclose(p, p_ref, atol=1e-12)


def test_tree_robot_matches_pinocchio(tree_robot):
    _check(tree_robot, 0)


def test_finger_matches_pinocchio(finger_robot):
    _check(finger_robot, 1)


@pytest.mark.parametrize("base", ["arm1", "neck0_mid"])
def test_moving_base_matches_pinocchio(tree_dir, tmp_path, base):
    """When joints move the base link, the base's own motion is subtracted (both routes)."""
    cfg = load_yaml(tree_dir / "sensors.yaml")
    cfg["base_link"] = base
    (tmp_path / "robot.urdf").write_text((tree_dir / "robot.urdf").read_text())
    save_yaml(cfg, tmp_path / "sensors.yaml")
    _check(load_robot(tmp_path), 2)


def test_moves_detects_links_fixed_to_base(tree_robot):
    kin = BatchKinematics(tree_robot)
    assert not kin.moves("waist")
    assert kin.moves("arm0")
