"""Real-robot conversions (TX40, TIAGo) against the README's facts and rigid-body dynamics."""

import os
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from diegocal.errors import InputFileError, LogFormatError
from diegocal.io import load_log, save_log
from diegocal.io.real import (
    TIAGO_JOINTS,
    RealOptions,
    excitation_window,
    load_tiago,
    load_tx40,
    reduce_urdf,
    smooth_derivatives,
    tiago_torque_from_effort,
    tx40_joint_from_motor,
    tx40_torque_from_motor,
)
from diegocal.robot import load_robot

REPO = Path(__file__).resolve().parents[2]
DATA = Path(os.environ.get("DIEGOCAL_REAL_DATA", REPO.parent / "shared" / "data" / "real"))
needs_data = pytest.mark.skipif(not (DATA / "tx40").is_dir(), reason=f"no real data at {DATA}")
needs_robots = pytest.mark.skipif(not (REPO / "robots" / "tiago" / "robot.urdf").exists(),
                                  reason="robots/tiago not built (scripts/convert_real.py)")


# ----------------------------------------------------------------------------- unit conversions
def test_tx40_first_row_is_the_urdf_zero():
    # README check: row 1 gives 50.265/32 = 70.685/45 = π/2 before the zero offsets
    row = np.array([[3.1958e-05, 50.265, -70.685, 0.0, 0.0, -0.00028762]])
    q = tx40_joint_from_motor(row)[0]
    assert 50.265 / 32 == pytest.approx(np.pi / 2, abs=1e-4)
    assert 70.685 / 45 == pytest.approx(np.pi / 2, abs=1e-4)
    np.testing.assert_allclose(q[1:3], 0.0, atol=2e-5)  # q2 - π/2, q3 + π/2
    assert q[0] == pytest.approx(3.1958e-05 / 32)
    assert q[5] == pytest.approx(-0.00028762 / 32)  # q6 = m6/32 - q5, q5 = 0


def test_tx40_wrist_coupling_round_trips():
    q = np.random.default_rng(0).uniform(-1, 1, (5, 6))
    motor = (q - [0, -np.pi / 2, np.pi / 2, 0, 0, 0]) @ np.diag([32, 32, 45, -48, 45, 32.0]).T
    motor[:, 5] += 32 * (q[:, 4])  # motor 6 = 32 (q5 + q6)
    np.testing.assert_allclose(tx40_joint_from_motor(motor), q, atol=1e-12)


def test_tx40_torques_follow_the_transpose_ratio():
    c = np.array([[1.0, 2.0, 3.0, 4.0, 5.0, 6.0]])
    np.testing.assert_allclose(tx40_torque_from_motor(c)[0],
                               [32, 64, 135, -192, 45 * 5 + 32 * 6, 192])


def test_tiago_effort_gains_and_torso_gravity():
    effort = np.array([[1.675, 0.032, 1.654, 0.056, 1.192, 0.0, 0.0, 0.0]])  # first row
    tau = tiago_torque_from_effort(effort)[0]
    np.testing.assert_allclose(tau, [1.675 + 9.81 * 18.5, 13.6 * 0.032, 13.6 * 1.654,
                                     -8.7 * 0.056, -8.7 * 1.192, 0, 0, 0])


def test_zero_phase_derivatives_of_a_sine():
    rate = 200.0
    t = np.arange(0, 20, 1 / rate)
    w = 2 * np.pi * 0.5
    q = np.sin(w * t)[:, None]
    qf, qd, qdd = smooth_derivatives(q, rate, cutoff_hz=5.0)
    inner = slice(400, -400)  # away from the filter's edge transients
    np.testing.assert_allclose(qf[inner, 0], np.sin(w * t[inner]), atol=1e-3)
    np.testing.assert_allclose(qd[inner, 0], w * np.cos(w * t[inner]), atol=1e-2)
    np.testing.assert_allclose(qdd[inner, 0], -w * w * np.sin(w * t[inner]), atol=3e-2)


def test_excitation_window_with_margin():
    qd = np.zeros((1000, 2))
    qd[300:700, 1] = 0.5
    assert excitation_window(qd, 100.0, threshold=0.1, margin_s=0.5) == (250, 750)
    assert excitation_window(np.zeros((10, 2)), 100.0) == (0, 10)


def test_missing_files_and_columns_are_clear_errors(tmp_path):
    with pytest.raises(InputFileError, match="no such file"):
        load_tx40(tmp_path)
    (tmp_path / "pos_read_data.csv").write_text("Joint_1,Joint_2\n1,2\n")
    (tmp_path / "curr_data.csv").write_text("Joint_1,Joint_2\n1,2\n")
    with pytest.raises(LogFormatError, match="missing columns"):
        load_tx40(tmp_path)


def test_reduce_urdf_folds_neutral_into_origin(tmp_path):
    src = tmp_path / "in.urdf"
    src.write_text("""<robot name="r">
      <link name="a"/><link name="b"/><link name="c"/>
      <joint name="j1" type="revolute"><parent link="a"/><child link="b"/>
        <origin xyz="0 0 0.1" rpy="0 0 0"/><axis xyz="0 0 1"/>
        <limit lower="0.5" upper="1.0" effort="1" velocity="1"/></joint>
      <joint name="j2" type="continuous"><parent link="b"/><child link="c"/>
        <origin xyz="0.2 0 0" rpy="0 0 0"/><axis xyz="0 1 0"/></joint>
    </robot>""")
    frozen = reduce_urdf(src, tmp_path / "out.urdf", keep=["j2"])
    assert frozen == {"j1": 0.5}
    full = pin.buildModelFromUrdf(str(src))
    red = pin.buildModelFromUrdf(str(tmp_path / "out.urdf"))
    assert list(red.names[1:]) == ["j2"] and red.nq == 1
    assert red.lowerPositionLimit[0] == pytest.approx(-np.pi)
    for x in (-0.7, 0.3):  # same placement of link c for j1 frozen at 0.5
        df, dr = full.createData(), red.createData()
        qf = np.array([0.5, np.cos(x), np.sin(x)])  # continuous joint: (cos, sin)
        pin.framesForwardKinematics(full, df, qf)
        pin.framesForwardKinematics(red, dr, np.array([x]))
        np.testing.assert_allclose(df.oMf[full.getFrameId("c")].homogeneous,
                                   dr.oMf[red.getFrameId("c")].homogeneous, atol=1e-12)
    with pytest.raises(InputFileError, match="no joints"):
        reduce_urdf(src, tmp_path / "x.urdf", keep=["nope"])


# ----------------------------------------------------------------------------- real recordings
@pytest.fixture(scope="module")
def tx40():
    return load_tx40(DATA / "tx40")


@pytest.fixture(scope="module")
def tiago():
    return load_tiago(DATA / "tiago")


def _rnea(robot, log):
    idx = [log.streams["q"].names.index(j) for j in robot.joint_names]
    q, qd, qdd = (log.streams[k].data[:, idx] for k in ("q", "qd", "qdd"))
    tau = np.array([pin.rnea(robot.model, robot.data, a, b, c)
                    for a, b, c in zip(q, qd, qdd, strict=True)])
    return q, qd, qdd, tau


@needs_data
def test_tx40_log_shape_window_and_round_trip(tx40, tmp_path):
    assert tx40.rate_hz == 200.0 and tx40.robot == "tx40"
    assert set(tx40.streams) == {"q", "qd", "qdd", "tau"}
    assert tx40.time[0] < 0.1 and 7.3 < tx40.time[-1] < 8.0  # README: moves for ~7.4 s
    save_log(tx40, tmp_path / "tx40.h5")
    back = load_log(tmp_path / "tx40.h5")
    np.testing.assert_array_equal(back.streams["tau"].data, tx40.streams["tau"].data)


@needs_data
@needs_robots
def test_tx40_matches_rnea_with_the_published_priors(tx40):
    """rigid body + the README's rotor inertia, friction, offsets and wrist-coupling terms."""
    robot = load_robot(REPO / "robots" / "tx40")
    q, qd, qdd, rb = _rnea(robot, tx40)
    meas = tx40.streams["tau"].select(robot.joint_names).data
    # raw rigid body alone: positively correlated on the big joints (measured 0.52, 0.69)
    for j in (0, 1):
        assert np.corrcoef(meas[:, j], rb[:, j])[0, 1] > 0.4
    fv = np.array([8.05, 5.53, 1.97, 1.11, 1.86, 0.65])
    fs = np.array([7.14, 8.26, 6.34, 2.48, 3.03, 0.282])
    ia = np.array([0.362, 0.362, 0.0988, 0.0313, 0.0468, 0.0105])
    off = np.array([0.392, 1.37, 0.326, -0.102, -0.0288, 0.127])
    model = rb + ia * qdd + fv * qd + fs * np.sign(qd) + off
    v6, a6 = qd[:, 4] + qd[:, 5], qdd[:, 4] + qdd[:, 5]  # motor 6 turns with q5 + q6
    coupling = 0.00964 * a6 + 0.616 * v6 + 1.95 * np.sign(v6)
    model[:, 4] += coupling
    model[:, 5] += coupling
    corr = [np.corrcoef(meas[:, j], model[:, j])[0, 1] for j in range(6)]
    assert min(corr) > 0.95  # measured 0.98-0.99
    rmse = np.sqrt(((meas - model) ** 2).mean())
    assert rmse < 3.5  # measured 3.00 N·m (FIGAROH: 2.84 fitted in-sample with coupling)


@needs_data
def test_tiago_log_window_and_streams(tiago):
    assert tiago.rate_hz == 100.0 and tiago.robot == "tiago"
    assert tiago.streams["q"].names == TIAGO_JOINTS
    assert tiago.streams["tau"].names == TIAGO_JOINTS[:5]  # wrist efforts left out
    # the README's excitation (rows 921-6791, 9.2-67.9 s) lies inside the detected window
    assert 5.0 < tiago.time[0] < 9.2 and 67.9 < tiago.time[-1] < 70.0
    np.testing.assert_allclose(np.diff(tiago.time), 0.01, atol=1e-9)
    readme = load_tiago(DATA / "tiago", RealOptions(cutoff_hz=5.0, window=(9.2, 67.9)))
    assert readme.time[0] >= 9.2 and readme.time[-1] < 67.9
    with_wrist = load_tiago(DATA / "tiago", wrist_tau=True)
    assert with_wrist.streams["tau"].names == TIAGO_JOINTS


@needs_data
@needs_robots
def test_tiago_matches_rnea_plus_friction(tiago):
    robot = load_robot(REPO / "robots" / "tiago")
    _, qd, _, rb = _rnea(robot, tiago)
    tau = tiago.streams["tau"]
    torso = robot.joint_index("torso_lift_joint")
    meas_torso = tau.column("torso_lift_joint")
    # the torso carries ~18.5 kg: rigid body and effort + g m agree to ~1 %
    assert abs(meas_torso.mean() - rb[:, torso].mean()) < 0.02 * abs(meas_torso.mean())
    for name in ("arm_1_joint", "arm_2_joint", "arm_3_joint", "arm_4_joint"):
        k = robot.joint_index(name)
        m = tau.column(name)
        A = np.column_stack([rb[:, k], qd[:, k], np.tanh(qd[:, k] / 0.01), np.ones_like(m)])
        x, *_ = np.linalg.lstsq(A, m, rcond=None)
        assert 0.5 < x[0] < 2.0, name  # the rigid-body torque enters with a positive, ~1 scale
        assert np.corrcoef(m, A @ x)[0, 1] > 0.95, name  # measured 0.98-0.99
    for name in ("arm_3_joint", "arm_4_joint"):  # gravity-loaded: rigid body alone correlates
        k = robot.joint_index(name)
        assert np.corrcoef(tau.column(name), rb[:, k])[0, 1] > 0.5  # measured 0.58, 0.82


@needs_robots
def test_bundled_real_robots_load():
    tx = load_robot(REPO / "robots" / "tx40")
    assert tx.joint_names == tuple(f"joint_{i}" for i in range(1, 7))
    ti = load_robot(REPO / "robots" / "tiago")
    assert set(ti.joint_names) == set(TIAGO_JOINTS)
    data = ti.model.createData()
    pin.computeSubtreeMasses(ti.model, data)
    assert data.mass[ti.model.getJointId("torso_lift_joint")] == pytest.approx(18.5, abs=0.1)
