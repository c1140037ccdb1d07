"""A joint and its child link may share a name (a common URDF habit); the link is what sensors mean."""

import textwrap

import numpy as np

from diegocal.robot import load_robot, predict_markers

URDF = """<robot name="same_names"><link name="base"/>
<link name="arm"><inertial><mass value="1"/>
  <inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial></link>
<joint name="arm" type="revolute"><parent link="base"/><child link="arm"/><axis xyz="0 0 1"/>
  <origin xyz="0 0 0.1"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint></robot>"""


def test_marker_on_link_named_like_its_joint(tmp_path):
    (tmp_path / "robot.urdf").write_text(URDF)
    (tmp_path / "sensors.yaml").write_text(textwrap.dedent("""\
        base_link: base
        pots: [{name: p, kind: rotary, joint: arm, gain: 1, bias: 0}]
        markers: [{name: m, link: arm, xyz: [0.1, 0, 0]}]
        """))
    robot = load_robot(tmp_path)
    x = predict_markers(robot, np.array([[0.5]]), np.array([[0.1, 0, 0]]), np.eye(3), np.zeros(3))
    np.testing.assert_allclose(x[0, 0], [0.1 * np.cos(0.5), 0.1 * np.sin(0.5), 0.1], atol=1e-12)
