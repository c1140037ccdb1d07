"""Any URDF Pinocchio loads (issue #15): continuous, prismatic, mimic, floating and planar joints;
the model is reduced to the joints the sensors and data use, the rest locked at a stated
configuration, and the reduced model's kinematics and dynamics equal the full model's with those
joints held (two routes agree). The full TIAGo URDF works as is for kinematic calibration and
dynamics."""

from __future__ import annotations

import os
import shutil
import sys
import sysconfig
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from diegocal.errors import RobotConfigError
from diegocal.io import save_yaml, write_text
from diegocal.robot import PointSet, load_robot
from diegocal.robot.urdf import load_urdf

INERTIAL = (
    '<inertial><mass value="{m}"/><origin xyz="0.02 0.01 0.03"/>'
    '<inertia ixx="2e-3" iyy="3e-3" izz="4e-3" ixy="1e-4" ixz="0" iyz="0"/></inertial>'
)


def _link(name, m=0.5):
    return f'<link name="{name}">{INERTIAL.format(m=m)}</link>'


GADGET = f"""<?xml version="1.0"?>
<robot name="gadget">
  <link name="world_link"/>
  {_link("base", 2.0)} {_link("cart")} {_link("wheel", 0.3)} {_link("upper")} {_link("fore")}
  {_link("tool", 0.2)} {_link("finger_a", 0.05)} {_link("finger_b", 0.05)} {_link("sled", 0.4)}
  <joint name="float" type="floating"><parent link="world_link"/><child link="base"/>
    <origin xyz="0 0 1.0"/></joint>
  <joint name="rail" type="prismatic"><parent link="base"/><child link="cart"/><origin xyz="0.1 0 0"/>
    <axis xyz="1 0 0"/><limit lower="-0.2" upper="0.2" effort="50" velocity="1"/></joint>
  <joint name="spin" type="continuous"><parent link="base"/><child link="wheel"/><origin xyz="0 0.2 -0.1"/>
    <axis xyz="0 1 0"/></joint>
  <joint name="shoulder" type="revolute"><parent link="cart"/><child link="upper"/>
    <origin xyz="0 0 0.1" rpy="0.2 0 0"/><axis xyz="0 0 1"/><limit lower="-2" upper="2" effort="5" velocity="3"/>
  </joint>
  <joint name="elbow" type="continuous"><parent link="upper"/><child link="fore"/><origin xyz="0.3 0 0"/>
    <axis xyz="0 0.6 0.8"/><limit effort="5" velocity="3"/></joint>
  <joint name="tool_fixed" type="fixed"><parent link="fore"/><child link="tool"/><origin xyz="0.25 0 0"/></joint>
  <joint name="finger_a" type="prismatic"><parent link="tool"/><child link="finger_a"/>
    <axis xyz="0 1 0"/><limit lower="0" upper="0.04" effort="5" velocity="1"/></joint>
  <joint name="finger_b" type="prismatic"><parent link="tool"/><child link="finger_b"/>
    <axis xyz="0 -1 0"/><limit lower="0" upper="0.04" effort="5" velocity="1"/><mimic joint="finger_a"/></joint>
  <joint name="plane" type="planar"><parent link="base"/><child link="sled"/><origin xyz="0 -0.2 0"/>
    <axis xyz="0 0 1"/></joint>
</robot>
"""

SENSORS = {
    "urdf": "robot.urdf",
    "base_link": "base",
    "pots": [
        {"name": "rail_enc", "kind": "encoder", "joint": "rail"},
        {"name": "shoulder_pot", "kind": "rotary", "joint": "shoulder", "gain": 1.1, "bias": 0.1},
        {"name": "elbow_pot", "kind": "rotary", "joint": "elbow", "gain": 0.9, "bias": -0.2},
    ],
    "markers": [
        {"name": "m_upper", "link": "upper", "xyz": [0.1, 0.02, 0.0]},
        {"name": "m_tool", "link": "tool", "xyz": [0.02, 0.0, 0.03]},
    ],
}


def _gadget(tmp_path, sensors=None) -> Path:
    d = tmp_path / "gadget"
    write_text(d / "robot.urdf", GADGET)
    save_yaml(SENSORS if sensors is None else sensors, d / "sensors.yaml")
    return d


def test_every_joint_type_loads_and_unused_joints_are_locked(tmp_path):
    robot = load_robot(_gadget(tmp_path))
    assert robot.joint_names == ("rail", "shoulder", "elbow")
    assert robot.model.nq == robot.model.nv == 3
    assert set(robot.locked) == {"float", "spin", "finger_a", "finger_b", "plane"}
    assert robot.locked["float"] == [0.0] * 6 + [1.0]  # the free-flyer at identity
    assert robot.locked["spin"] == 0.0 and robot.locked["plane"] == [0.0, 0.0, 1.0, 0.0]
    k = robot.joint_index("elbow")
    assert (robot.lower[k], robot.upper[k]) == pytest.approx((-np.pi, np.pi))  # continuous -> revolute


def test_stated_locked_configuration_is_used(tmp_path):
    sensors = dict(SENSORS, locked={"finger_a": 0.03, "spin": 1.0})
    robot = load_robot(_gadget(tmp_path, sensors))
    assert robot.locked["finger_a"] == 0.03 and robot.locked["spin"] == 1.0
    full = load_urdf(robot.source / "robot.urdf").model
    q = pin.neutral(full)
    for name, value in robot.locked.items():
        jm = full.joints[full.getJointId(name)]
        q[jm.idx_q : jm.idx_q + jm.nq] = value
    pin.framesForwardKinematics(full, data := full.createData(), q)
    reduced = robot.model.createData()
    pin.framesForwardKinematics(robot.model, reduced, np.zeros(3))
    for link in ("finger_a", "wheel", "tool"):
        a = data.oMf[full.getFrameId(link, pin.FrameType.BODY)]
        b = reduced.oMf[robot.frame_id(link)]
        np.testing.assert_allclose(b.homogeneous, a.homogeneous, atol=1e-12)


def test_reduced_dynamics_equal_the_full_model_with_locked_joints_still(tmp_path):
    """rnea of the reduced model = the full model's on the kept joints, the locked ones held still
    at their configuration (their links' inertias are carried by the reduced model's links)."""
    robot = load_robot(_gadget(tmp_path, dict(SENSORS, locked={"finger_a": 0.02})))
    full = load_urdf(robot.source / "robot.urdf").model
    rng = np.random.default_rng(0)
    for _ in range(5):
        qr, vr, ar = rng.uniform(-1, 1, 3) * [0.2, 1, 1], rng.normal(size=3), rng.normal(size=3)
        q, v, a = pin.neutral(full), np.zeros(full.nv), np.zeros(full.nv)
        for name, value in robot.locked.items():
            jm = full.joints[full.getJointId(name)]
            q[jm.idx_q : jm.idx_q + jm.nq] = value
        idx = []
        for i, name in enumerate(robot.joint_names):
            jm = full.joints[full.getJointId(name)]
            q[jm.idx_q], v[jm.idx_v], a[jm.idx_v] = qr[i], vr[i], ar[i]
            idx.append(jm.idx_v)
        tau_full = pin.rnea(full, full.createData(), q, v, a)[idx]
        tau_red = pin.rnea(robot.model, robot.model.createData(), qr, vr, ar)
        np.testing.assert_allclose(tau_red, tau_full, rtol=1e-10, atol=1e-10)


def test_urdf_file_alone_keeps_every_one_dof_joint(tmp_path):
    urdf = _gadget(tmp_path) / "robot.urdf"
    robot = load_robot(urdf)  # dynamics alone: no sensors.yaml, the base is the root link
    assert set(robot.joint_names) == {"rail", "spin", "shoulder", "elbow", "finger_a", "finger_b"}
    assert set(robot.locked) == {"float", "plane"} and robot.sensors.base_link == "world_link"
    assert robot.reference == str(urdf.resolve())
    only = load_robot(urdf, joints=("shoulder", "elbow"))
    assert only.joint_names == ("shoulder", "elbow")
    from diegocal.errors import UnknownNameError

    with pytest.raises(UnknownNameError, match="'elbw' of the joint streams .* not a joint of robot.urdf — did you"):
        load_robot(urdf, joints=("shoulder", "elbw"))
    # another device's channel (a gripper's motor) is no misspelling: left to the stream readers
    assert load_robot(urdf, joints=("shoulder", "elbow", "gripper_motor")).joint_names == ("shoulder", "elbow")


def test_a_used_multi_dof_joint_is_one_clear_error(tmp_path):
    with pytest.raises(RobotConfigError, match="'float' is a free-flyer joint .*locked: "):
        load_robot(_gadget(tmp_path) / "robot.urdf", joints=("float",))
    sensors = dict(SENSORS, markers=[*SENSORS["markers"], {"name": "m_sled", "link": "sled", "xyz": [0, 0, 0]}])
    with pytest.raises(RobotConfigError, match="'plane' is a planar joint"):
        load_robot(_gadget(tmp_path, sensors))


# ----------------------------------------------------------------------------- TIAGo
REPO = Path(__file__).resolve().parents[2]
DATA = Path(os.environ.get("DIEGOCAL_REAL_DATA", REPO.parent / "shared" / "data" / "real"))
ERD = Path(sysconfig.get_paths()["purelib"]) / "cmeel.prefix" / "share" / "example-robot-data" / "robots"
ARM = ("torso_lift_joint",) + tuple(f"arm_{i}_joint" for i in range(1, 8))


def tiago_urdf() -> Path:
    """The full TIAGo URDF of the real recording (else example-robot-data's TIAGo)."""
    for path in (DATA / "tiago" / "tiago_hey5.urdf", ERD / "tiago_description" / "robots" / "tiago.urdf"):
        if path.is_file():
            return path
    pytest.skip("no full TIAGo URDF (real data or example-robot-data)")


def tiago_sensors() -> dict:
    """Encoders on the torso and arm, a rigid cluster of four markers on the hand, two markers on
    the upper arm and two on the forearm; the mocap frame is fixed to the mobile base."""
    cluster = [[0.05, 0.0, 0.0], [0.0, 0.05, 0.0], [0.0, 0.0, 0.07], [0.04, 0.04, 0.03]]
    markers = [{"name": f"hand_{i}", "link": "hand_palm_link", "xyz": x} for i, x in enumerate(cluster)]
    markers += [
        {"name": "upper_a", "link": "arm_3_link", "xyz": [0.0, 0.05, 0.0]},
        {"name": "upper_b", "link": "arm_3_link", "xyz": [0.05, 0.0, 0.1]},
        {"name": "fore_a", "link": "arm_5_link", "xyz": [0.0, 0.05, 0.0]},
        {"name": "fore_b", "link": "arm_5_link", "xyz": [0.05, 0.0, 0.05]},
    ]
    pots = [{"name": j.replace("_joint", "_enc"), "kind": "encoder", "joint": j, "bias": 0.0} for j in ARM]
    return {"urdf": "robot.urdf", "base_link": "base_footprint", "pots": pots, "markers": markers}


def test_full_tiago_urdf_calibrates_torso_and_arm(tmp_path):
    from diegocal.sim.kinematics import KinematicsOptions, simulate_kinematics
    from diegocal.stac import calibrate
    from diegocal.stac.calibration import Calibration
    from diegocal.stac.model import Observation

    d = tmp_path / "tiago"
    d.mkdir()
    shutil.copy(tiago_urdf(), d / "robot.urdf")  # as is
    save_yaml(tiago_sensors(), d / "sensors.yaml")
    robot = load_robot(d)
    assert robot.joint_names == ARM and len(robot.locked) >= 40  # wheels, casters, head, hand
    log = simulate_kinematics(robot, KinematicsOptions(duration=20.0, rate_hz=50.0), np.random.default_rng(7))
    truth = Calibration.from_dict(log.truth.params)
    cal = calibrate(log.without_truth(), robot).calibration
    obs = Observation(log.without_truth(), robot)
    obs.check_observable()
    free = ~obs.fixed_bias
    # gauges: the lift moves every marker along a fixed axis (the mocap frame's translation takes
    # its offset), arm_1 turns about the lift's axis (the mocap frame's rotation), and arm_7's
    # markers are all on its own link (the hand cluster turns with its offset)
    assert {g["joint"] for g in cal.gauges} == {"torso_lift_joint", "arm_1_joint", "arm_7_joint"}
    assert free.sum() == len(ARM) - 3
    b_equiv = obs.gauge_equivalent_bias(truth.gain, truth.bias, cal.bias)
    z = (cal.bias - b_equiv) / cal.bias_se
    assert np.all(np.abs(z[free]) < 4.5), z
    assert np.abs(cal.bias - b_equiv)[free].max() < 0.01  # rad (m for the torso)
    err = np.linalg.norm(cal.marker_xyz - truth.marker_xyz, axis=1)[obs.gauge_free_markers()]
    assert err.max() < 0.005


def test_full_tiago_urdf_dynamics_equal_the_hand_reduced_copy():
    """The full URDF reduced to torso + arm (locked at 0, as scripts/convert_real.py fixed them)
    has the dynamics of robots/tiago."""
    full = load_robot(tiago_urdf(), joints=ARM)
    bundled = REPO / "robots" / "tiago"
    if tiago_urdf().name != "tiago_hey5.urdf" or not (bundled / "robot.urdf").is_file():
        pytest.skip("robots/tiago was made from the real recording's URDF")
    ref = load_robot(bundled)
    assert full.joint_names == ref.joint_names == ARM
    rng = np.random.default_rng(1)
    for _ in range(5):
        q = rng.uniform(ref.lower, ref.upper)
        v, a = rng.normal(size=8), rng.normal(size=8)
        t_full = pin.rnea(full.model, full.model.createData(), q, v, a)
        t_ref = pin.rnea(ref.model, ref.model.createData(), q, v, a)
        np.testing.assert_allclose(t_full, t_ref, rtol=1e-9, atol=1e-9)
    pts = PointSet(("hand_palm_link", "arm_4_link"), np.array([[0.01, 0.02, 0.03], [0.0, 0.1, 0.0]]))
    q = rng.uniform(ref.lower, ref.upper, (3, 8))
    np.testing.assert_allclose(full.points(q, pts), ref.points(q, pts), atol=1e-12)


def test_full_tiago_calibration_loses_exactly_its_three_gauges(tmp_path, sample_q):
    """The calibration Jacobian of the TIAGo set-up above (test_identifiability's construction)
    loses exactly the directions gauge_joints names: the lift and arm_1 (root: the mocap frame),
    arm_7 (leaf: the hand cluster); fixing their encoders' biases leaves everything identifiable."""
    sys.path.insert(0, str(Path(__file__).parent))
    from test_identifiability import bias_to_fix, calibration_jacobian, normalised_singular_values

    from diegocal.robot import gauge_joints

    d = tmp_path / "tiago"
    d.mkdir()
    shutil.copy(tiago_urdf(), d / "robot.urdf")
    save_yaml(tiago_sensors(), d / "sensors.yaml")
    robot = load_robot(d)
    assert set(gauge_joints(robot)) == {"torso_lift_joint", "arm_1_joint", "arm_7_joint"}
    J, col = calibration_jacobian(robot, sample_q(robot, np.random.default_rng(3), 6))
    gain = col["gain"] + np.arange(len(ARM))  # encoders: gain fixed at 1, not an unknown
    J = np.delete(J, gain, axis=1)
    bias = col["bias"] - len(ARM) + np.array([bias_to_fix(robot, j) for j in gauge_joints(robot)])
    assert (normalised_singular_values(J) < 1e-9).sum() == 3
    assert normalised_singular_values(np.delete(J, bias, axis=1)).min() > 1e-5


def test_dynamics_from_the_urdf_alone_end_to_end(tmp_path):
    """`--robot` naming the URDF file itself (dynamics alone): simulate, sgp-fit and predict, the
    last two without --robot (the log names its URDF, the model records it); a directory with
    robot.urdf and no sensors.yaml is the same robot."""
    from typer.testing import CliRunner

    from diegocal.cli import app
    from diegocal.io import load_log, load_yaml

    urdf = _gadget(tmp_path) / "robot.urdf"
    run = CliRunner().invoke
    res = run(app, ["simulate", "dynamics", "--robot", str(urdf), "-o", str(tmp_path / "d.h5"), "--duration", "6",
                    "--rate", "50", "-q"])
    assert res.exit_code == 0, res.output
    assert load_log(tmp_path / "d.h5").robot == str(urdf.resolve())
    res = run(app, ["sgp-fit", str(tmp_path / "d.h5"), "--model", "pr", "-q"])
    assert res.exit_code == 0, res.output
    head = load_yaml(tmp_path / "d.sgp" / "sgp.yaml")["robot"]
    assert head["dir"] == str(urdf.resolve()) and set(head["locked"]) == {"float", "plane"}
    res = run(app, ["predict", str(tmp_path / "d.sgp"), str(tmp_path / "d.h5"), "-o", str(tmp_path / "p.h5")])
    assert res.exit_code == 0, res.output
    (urdf.parent / "sensors.yaml").unlink()
    same = load_robot(urdf.parent)
    assert same.joint_names == load_robot(urdf).joint_names and same.source == urdf
