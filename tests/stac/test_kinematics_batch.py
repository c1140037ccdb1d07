"""Two routes agree: vectorised kinematics equals Robot.points / points_jacobian (Pinocchio), and
the Jacobian-free sums (points_normal, points_velocity, points_project) equal the products of the
Pinocchio Jacobian."""

import numpy as np
import pytest
import synth

from diegocal.errors import RobotConfigError
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
        _check_sums(kin, poses, x, pts.links, J_ref, rng)
    links = list(robot.sensors.marker_names and [m.link for m in robot.sensors.markers])
    R_ref, p_ref = robot.link_poses(q, links)
    R, p = kin.link_poses(poses, links)
    np.testing.assert_allclose(R, R_ref, atol=1e-12)
    np.testing.assert_allclose(p, p_ref, atol=1e-12)


def _check_sums(kin, poses, x, links, J, rng):
    """Σ w JᵀJ, Σ Jᵀf, J u and fᵀJ without J equal the dense products (Pinocchio's J)."""
    w = rng.uniform(0.0, 2.0, x.shape[:2])
    f = rng.normal(size=x.shape)
    u = rng.normal(size=(x.shape[0], J.shape[-1]))
    H, g = kin.points_normal(poses, x, links, w, f)
    np.testing.assert_allclose(H, np.einsum("bmcj,bm,bmck->bjk", J, w, J), atol=1e-12)
    np.testing.assert_allclose(g, np.einsum("bmcj,bmc->bj", J, f), atol=1e-12)
    n = J.shape[-1]  # the same sums as the blocks of coarser partitions (the q-phase's, pots joining groups)
    for blocks in ((np.arange(n),), (np.arange(0, n, 2), np.arange(1, n, 2))):
        try:
            Hb, gb = kin.points_normal_blocks(poses, x, links, w, f, blocks)
        except RobotConfigError:  # a partition that splits joints that move points in common
            assert len(blocks) > 1
            continue
        np.testing.assert_array_equal(gb, g)
        for ix, h in zip(blocks, Hb, strict=True):
            np.testing.assert_allclose(h, H[:, ix[:, None], ix], atol=1e-12)
    np.testing.assert_allclose(kin.points_velocity(poses, x, links, u), np.einsum("bmcj,bj->bmc", J, u), atol=1e-12)
    fJ = np.einsum("bmcj,bmc->bmj", J, f)
    np.testing.assert_allclose(kin.points_project(poses, x, links, f), fJ, atol=1e-12)
    cols = np.arange(0, J.shape[-1], 2)
    np.testing.assert_allclose(kin.points_project(poses, x, links, f, cols), fJ[..., cols], atol=1e-12)


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


def test_link_frame_off_its_joint(tree_dir, tmp_path):
    """A link on a fixed joint (Pinocchio merges it into its parent's joint, with a placement that is
    not the identity), and a marker on it, take the general route."""
    urdf = (tree_dir / "robot.urdf").read_text()
    tool = (
        '<link name="tool"/><joint name="tool_mount" type="fixed"><parent link="arm3"/><child link="tool"/>'
        '<origin xyz="0.05 0.01 -0.02" rpy="0.3 -0.2 0.1"/></joint>'
    )
    (tmp_path / "robot.urdf").write_text(urdf.replace("</robot>", tool + "</robot>"))
    cfg = load_yaml(tree_dir / "sensors.yaml")
    cfg["markers"].append({"name": "m_tool", "link": "tool", "xyz": [0.01, 0.02, 0.03]})
    save_yaml(cfg, tmp_path / "sensors.yaml")
    robot = load_robot(tmp_path)
    _check(robot, 3)
    assert not np.allclose(BatchKinematics(robot).link_info(["tool"])[1], np.eye(3))
