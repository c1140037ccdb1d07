"""`diegocal import` against the robot a log is for: prismatic units, mimic joints, xacro descriptions."""

import numpy as np
import pytest

from diegocal.errors import InputFileError
from diegocal.io.importers import UnitError, import_log, parse_map
from diegocal.robot import load_robot
from diegocal.robot.urdf import load_urdf
from tests.io.labfiles import write_bag

INERTIA = '<inertial><mass value="0.5"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial>'

#: An arm with a two-finger gripper as labs describe it: a macro per finger, the right one a mimic.
GRIPPER_XACRO = f"""<?xml version="1.0"?>
<robot name="picker" xmlns:xacro="http://www.ros.org/wiki/xacro">
  <xacro:property name="reach" value="0.3"/>
  <xacro:macro name="body" params="name"><link name="${{name}}">{INERTIA}</link></xacro:macro>
  <xacro:macro name="finger" params="side sign leader:=''">
    <xacro:body name="${{side}}_finger"/>
    <joint name="${{side}}_finger_joint" type="prismatic">
      <parent link="hand"/><child link="${{side}}_finger"/><origin xyz="0 ${{sign * 0.02}} 0"/>
      <axis xyz="0 ${{sign}} 0"/><limit lower="0" upper="0.04" effort="20" velocity="0.1"/>
      <xacro:if value="${{leader != ''}}"><mimic joint="${{leader}}" multiplier="1" offset="0"/></xacro:if>
    </joint>
  </xacro:macro>
  <xacro:body name="base"/><xacro:body name="hand"/>
  <joint name="shoulder" type="revolute">
    <parent link="base"/><child link="hand"/><origin xyz="0 0 ${{reach}}"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="10" velocity="2"/>
  </joint>
  <xacro:finger side="left" sign="1"/>
  <xacro:finger side="right" sign="-1" leader="left_finger_joint"/>
</robot>
"""


@pytest.fixture
def picker(tmp_path):
    path = tmp_path / "picker.urdf.xacro"
    path.write_text(GRIPPER_XACRO)
    return path


def _arm_and_gripper_bag(tmp_path, both_fingers=True):
    """shoulder at 100 Hz, the gripper driver at 100 Hz too (3 ms later), publishing both fingers."""
    t = np.arange(200) * 0.01
    arm = np.sin(t)[:, None]
    tg = 0.003 + np.arange(199) * 0.01
    finger = 0.02 + 0.01 * np.sin(tg)
    names = ["left_finger_joint", "right_finger_joint"] if both_fingers else ["left_finger_joint"]
    grip = np.column_stack([finger, finger])[:, : len(names)]
    effort = np.column_stack([np.full_like(tg, 2.0), np.full_like(tg, 0.5)])[:, : len(names)]
    return write_bag(tmp_path / f"pick{len(names)}.bag", "ros1", ["shoulder"], t, arm, None, 3 * arm,
                     publishers=[(names, tg, grip, effort)])


def test_xacro_loads_with_its_mimic_joint(tmp_path, picker):
    loaded = load_urdf(picker)
    assert list(loaded.model.names) == ["universe", "shoulder", "left_finger_joint", "right_finger_joint"]
    assert loaded.mimic == {"right_finger_joint": ("left_finger_joint", 1.0, 0.0)}
    folder = tmp_path / "picker"
    folder.mkdir()
    (folder / "robot.urdf.xacro").write_text(picker.read_text())
    (folder / "sensors.yaml").write_text("urdf: robot.urdf.xacro\nbase_link: base\n")
    assert load_robot(folder).model.nq == 3  # a robot directory may name a xacro description


def test_mimic_finger_is_driven_from_its_leader(tmp_path, picker):
    path = _arm_and_gripper_bag(tmp_path)
    result = import_log([path], parse_map({"robot": str(picker), "sources": {"pick": {"zero_time": True}}}))
    q, tau = result.log.streams["q"], result.log.streams["tau"]
    assert q.names == tau.names == ("shoulder", "left_finger_joint")  # one coordinate for the pair
    np.testing.assert_allclose(tau.column("left_finger_joint"), 2.0 + 1.0 * 0.5)  # τ_l + m τ_f
    assert any("mimic: right_finger_joint = 1 × left_finger_joint +0, driven from left_finger_joint" in n
               for n in result.notes), result.notes
    rows = {r[0]: r[3] for r in result.streams}
    assert rows["q"] == "rad; m for left_finger_joint (prismatic)"
    assert rows["tau"] == "N·m; N for left_finger_joint (prismatic)"
    only = _arm_and_gripper_bag(tmp_path, both_fingers=False)  # a driver publishing the leader only
    notes = import_log([only], parse_map({"robot": str(picker)})).notes
    assert any("no channel of its own" in n for n in notes)


def test_prismatic_joints_take_linear_units(tmp_path):
    # the case: TIAGo's torso lift is prismatic; its effort is a force (N), not N·m
    t = np.arange(50) * 0.01
    values = np.column_stack([0.1 + 0.01 * t, np.sin(t)])
    lines = ["time,torso_mm,arm_deg,torso_f,arm_t"] + [f"{x},{1000 * a},{np.degrees(b)},{30.0},{2.0}"
                                                      for x, (a, b) in zip(t, values, strict=True)]
    (tmp_path / "tiago.csv").write_text("\n".join(lines) + "\n")
    streams = {"q": {"columns": {"torso_mm": "torso_lift_joint", "arm_deg": "arm_1_joint"},
                     "unit": {"torso_lift_joint": "mm", "arm_1_joint": "deg"}},
               "tau": {"columns": {"torso_f": "torso_lift_joint", "arm_t": "arm_1_joint"}, "unit": ["N", "Nm"]}}
    result = import_log([tmp_path / "tiago.csv"], parse_map({"robot": "tiago", "streams": streams}))
    np.testing.assert_allclose(result.log.streams["q"].data, values, atol=1e-12)
    rows = {r[0]: r[3] for r in result.streams}
    assert rows["q"] == "mm/deg -> rad; m for torso_lift_joint (prismatic)"
    assert rows["tau"] == "N/Nm -> N·m; N for torso_lift_joint (prismatic)"
    streams["tau"]["unit"] = "Nm"
    with pytest.raises(UnitError, match="tau of 'torso_lift_joint', a prismatic joint, is in N, not Nm"):
        import_log([tmp_path / "tiago.csv"], parse_map({"robot": "tiago", "streams": streams}))
    streams["tau"]["unit"] = ["N", "Nm"]
    streams["q"]["unit"] = "deg"
    with pytest.raises(UnitError, match="q of 'torso_lift_joint', a prismatic joint, is in m, not deg"):
        import_log([tmp_path / "tiago.csv"], parse_map({"robot": "tiago", "streams": streams}))


def test_a_robot_that_cannot_be_found_or_expanded(tmp_path, caplog):
    (tmp_path / "a.csv").write_text("time,q.j1\n0,0\n0.01,0.1\n")
    with caplog.at_level("WARNING", logger="diegocal"):
        log = import_log([tmp_path / "a.csv"], robot="no_such_robot").log
    assert log.robot == "no_such_robot"
    assert any("robot 'no_such_robot' not found" in r.getMessage() for r in caplog.records)
    ros = tmp_path / "ros.urdf.xacro"
    ros.write_text('<robot name="r" xmlns:xacro="http://www.ros.org/wiki/xacro">'
                   '<xacro:include filename="$(find my_robot_description)/urdf/arm.xacro"/></robot>')
    with pytest.raises(InputFileError, match=r"ros.urdf.xacro: xacro cannot expand it .*\$\(find \.\.\.\) needs ROS"):
        import_log([tmp_path / "a.csv"], robot=str(ros))
