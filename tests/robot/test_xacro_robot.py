"""A xacro description is a robot like a URDF (from the importer work): ``--robot arm.urdf.xacro``
loads and resolves, a fitted model's robot copy is the expanded URDF, and the robot's hash covers
what the expansion read (an edit of an included file is another robot)."""

from __future__ import annotations

import numpy as np
import pytest

from diegocal.errors import RobotConfigError
from diegocal.io import load_yaml, save_yaml
from diegocal.io.bundle import robot_hash, robot_record, same_robot, save_robot_copy
from diegocal.robot import PointSet, load_robot, resolve_robot_dir

INERTIA = '<inertial><mass value="0.5"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial>'
PARTS = f"""<?xml version="1.0"?>
<robot xmlns:xacro="http://www.ros.org/wiki/xacro">
  <xacro:macro name="segment" params="name parent length">
    <link name="${{name}}">{INERTIA}</link>
    <joint name="${{name}}_joint" type="revolute"><parent link="${{parent}}"/><child link="${{name}}"/>
      <origin xyz="0 0 ${{length}}"/><axis xyz="0 1 0"/><limit lower="-2" upper="2" effort="5" velocity="2"/>
    </joint>
  </xacro:macro>
</robot>
"""
ARM = f"""<?xml version="1.0"?>
<robot name="twolink" xmlns:xacro="http://www.ros.org/wiki/xacro">
  <xacro:include filename="parts.xacro"/>
  <xacro:property name="reach" value="0.3"/>
  <link name="base">{INERTIA}</link>
  <xacro:segment name="upper" parent="base" length="0.1"/>
  <xacro:segment name="fore" parent="upper" length="${{reach}}"/>
</robot>
"""


@pytest.fixture
def arm(tmp_path):
    (tmp_path / "parts.xacro").write_text(PARTS)
    path = tmp_path / "arm.urdf.xacro"
    path.write_text(ARM)
    return path


def test_a_xacro_file_loads_and_resolves_like_a_urdf(arm):
    robot = load_robot(arm)
    assert robot.name == "twolink" and robot.joint_names == ("upper_joint", "fore_joint")
    assert robot.source == arm
    assert resolve_robot_dir(str(arm), None) == arm
    assert resolve_robot_dir(None, str(arm)) == arm  # a log naming its robot's xacro
    x = robot.points(np.zeros((1, 2)), PointSet(("fore",), np.zeros((1, 3))))
    np.testing.assert_allclose(x[0, 0], [0.0, 0.0, 0.4])  # 0.1 + the reach property
    with pytest.raises(RobotConfigError, match="URDF or xacro"):
        resolve_robot_dir(str(arm.with_name("missing.urdf.xacro")), None)


def test_robot_copy_is_the_expanded_urdf(arm, tmp_path):
    robot = load_robot(arm)
    copy = tmp_path / "copy"
    save_robot_copy(robot, copy)
    text = (copy / "robot.urdf").read_text()
    assert "<xacro:" not in text and "${" not in text and 'name="fore_joint"' in text
    assert load_yaml(copy / "sensors.yaml")["urdf"] == "robot.urdf"
    again = load_robot(copy)
    assert again.joint_names == robot.joint_names
    q = np.array([[0.3, -0.7]])
    pts = PointSet(("fore",), np.array([[0.1, 0.0, 0.05]]))
    np.testing.assert_allclose(again.points(q, pts), robot.points(q, pts))


def test_the_hash_covers_the_included_files(arm, tmp_path):
    record = robot_record(load_robot(arm))
    assert record["dir"] == str(arm.resolve()) and record["hash"] == robot_hash(arm)
    folder = tmp_path / "dir"
    folder.mkdir()
    (folder / "parts.xacro").write_text(PARTS)
    (folder / "robot.urdf.xacro").write_text(ARM)
    save_yaml({"urdf": "robot.urdf.xacro", "base_link": "base"}, folder / "sensors.yaml")
    before = robot_hash(folder)
    assert load_robot(folder).joint_names == ("upper_joint", "fore_joint")
    (arm.parent / "parts.xacro").write_text(PARTS.replace('lower="-2"', 'lower="-1.5"'))
    (folder / "parts.xacro").write_text(PARTS.replace('lower="-2"', 'lower="-1.5"'))
    assert robot_hash(arm) != record["hash"] and not same_robot(record, arm)
    after = robot_hash(folder)
    assert after != before
    folder.rename(tmp_path / "moved")
    assert robot_hash(tmp_path / "moved") == after  # where it lies is not hashed (xacro's banner names it)
