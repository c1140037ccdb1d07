"""The real-robot logs that ship in sample_data/real (TX40, TIAGo): their conversions, as the maps
beside them state them, against the README's facts, and the logs against rigid-body dynamics."""

import os
from dataclasses import replace
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from diegocal.errors import InputFileError
from diegocal.io import load_log, save_log
from diegocal.io.importers import MapError, excitation_window, import_log, load_map
from diegocal.io.urdf import reduce_urdf
from diegocal.robot import load_robot

REPO = Path(__file__).resolve().parents[2]
SAMPLE = REPO / "sample_data" / "real"
RAW = Path(os.environ.get("DIEGOCAL_REAL_DATA", REPO.parent / "shared" / "data" / "real"))
TIAGO_JOINTS = ("torso_lift_joint",) + tuple(f"arm_{i}_joint" for i in range(1, 8))
TX40_COLUMNS = [f"Joint_{i}" for i in range(1, 7)]


def _tx40_files(tmp_path, motor, current):
    for fname, rows in (("pos_read_data.csv", motor), ("curr_data.csv", current)):
        lines = [",".join(TX40_COLUMNS)] + [",".join(repr(float(v)) for v in r) for r in rows]
        (tmp_path / fname).write_text("\n".join(lines) + "\n")
    return [tmp_path / "pos_read_data.csv", tmp_path / "curr_data.csv"]


def _tx40_convert(tmp_path, motor, current):
    motor, current = np.atleast_2d(motor), np.atleast_2d(current)
    if motor.shape[0] == 1:  # a log needs a time base: repeat the row
        motor, current = np.repeat(motor, 2, axis=0), np.repeat(current, 2, axis=0)
    mapping = replace(load_map(SAMPLE / "tx40.map.yaml"), filter=None, derive=(), window=None, clock=None)
    log = import_log(_tx40_files(tmp_path, motor, current), mapping).log
    return log.streams["q"].data, log.streams["tau"].data


# ----------------------------------------------------------------------------- unit conversions
def test_tx40_first_row_is_the_urdf_zero(tmp_path):
    # README check: row 1 gives 50.265/32 = 70.685/45 = π/2 before the zero offsets
    row = np.array([[3.1958e-05, 50.265, -70.685, 0.0, 0.0, -0.00028762]])
    q = _tx40_convert(tmp_path, row, np.zeros_like(row))[0][0]
    assert 50.265 / 32 == pytest.approx(np.pi / 2, abs=1e-4)
    assert 70.685 / 45 == pytest.approx(np.pi / 2, abs=1e-4)
    np.testing.assert_allclose(q[1:3], 0.0, atol=2e-5)  # q2 - π/2, q3 + π/2
    assert q[0] == pytest.approx(3.1958e-05 / 32)
    assert q[5] == pytest.approx(-0.00028762 / 32)  # q6 = m6/32 - q5, q5 = 0


def test_tx40_wrist_coupling_round_trips(tmp_path):
    q = np.random.default_rng(0).uniform(-1, 1, (5, 6))
    motor = (q - [0, -np.pi / 2, np.pi / 2, 0, 0, 0]) @ np.diag([32, 32, 45, -48, 45, 32.0]).T
    motor[:, 5] += 32 * (q[:, 4])  # motor 6 = 32 (q5 + q6)
    np.testing.assert_allclose(_tx40_convert(tmp_path, motor, np.zeros_like(motor))[0], q, atol=1e-12)


def test_tx40_torques_follow_the_transpose_ratio(tmp_path):
    c = np.array([[1.0, 2.0, 3.0, 4.0, 5.0, 6.0]])
    np.testing.assert_allclose(_tx40_convert(tmp_path, np.zeros_like(c), c)[1][0],
                               [32, 64, 135, -192, 45 * 5 + 32 * 6, 192])


def _tiago_files(tmp_path, t, position, effort):
    for kind, values in (("position", position), ("effort", effort)):
        head = ["t"] + [f"- {j}_{kind}" for j in TIAGO_JOINTS]
        rows = [",".join(repr(float(v)) for v in [ti, *row]) for ti, row in zip(t, values, strict=True)]
        (tmp_path / f"tiago_{kind}.csv").write_text(",".join(head) + "\n" + "\n".join(rows) + "\n")
    return [tmp_path / "tiago_position.csv", tmp_path / "tiago_effort.csv"]


def test_tiago_effort_gains_and_torso_gravity(tmp_path):
    effort = np.array([[1.675, 0.032, 1.654, 0.056, 1.192, 0.0, 0.0, 0.0]])  # first row
    files = _tiago_files(tmp_path, [0.0, 0.0108], np.zeros((2, 8)), np.repeat(effort, 2, axis=0))
    mapping = replace(load_map(SAMPLE / "tiago.map.yaml"), filter=None, derive=(), window=None, clock=None)
    tau = import_log(files, mapping).log.streams["tau"]
    assert tau.names == TIAGO_JOINTS[:5]  # the wrist efforts are left out
    np.testing.assert_allclose(tau.data[0], [1.675 + 9.81 * 18.5, 13.6 * 0.032, 13.6 * 1.654,
                                             -8.7 * 0.056, -8.7 * 1.192])


def test_tiago_jittered_stamps_are_read_on_a_uniform_100_hz_grid(tmp_path):
    rng = np.random.default_rng(1)
    t = np.cumsum(rng.uniform(0.0077, 0.0123, 400)) - 0.0077  # the recording's jitter
    q = np.column_stack([np.sin(t + k) for k in range(8)])
    files = _tiago_files(tmp_path, t, q, np.zeros((t.size, 8)))
    mapping = replace(load_map(SAMPLE / "tiago.map.yaml"), filter=None, derive=(), window=None)
    log = import_log(files, mapping).log
    assert log.rate_hz == 100.0 and log.time[0] == t[0]
    np.testing.assert_allclose(np.diff(log.time), 0.01, atol=1e-9)
    np.testing.assert_array_equal(log.streams["q"].data[:, 3], np.interp(log.time, t, q[:, 3]))


def test_missing_files_and_columns_are_clear_errors(tmp_path):
    mapping = load_map(SAMPLE / "tx40.map.yaml")
    with pytest.raises(InputFileError, match="no such file"):
        import_log([tmp_path / "pos_read_data.csv", tmp_path / "curr_data.csv"], mapping)
    (tmp_path / "pos_read_data.csv").write_text("Joint_1,Joint_2\n1,2\n")
    (tmp_path / "curr_data.csv").write_text("Joint_1,Joint_2\n1,2\n")
    with pytest.raises(MapError, match="no column 'Joint_3'"):
        import_log([tmp_path / "pos_read_data.csv", tmp_path / "curr_data.csv"], mapping)


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
    return load_log(SAMPLE / "tx40.h5")


@pytest.fixture(scope="module")
def tiago():
    return load_log(SAMPLE / "tiago.h5")


def _rnea(robot, log):
    idx = [log.streams["q"].names.index(j) for j in robot.joint_names]
    q, qd, qdd = (log.streams[k].data[:, idx] for k in ("q", "qd", "qdd"))
    tau = np.array([pin.rnea(robot.model, robot.data, a, b, c)
                    for a, b, c in zip(q, qd, qdd, strict=True)])
    return q, qd, qdd, tau


def test_tx40_log_shape_window_and_round_trip(tx40, tmp_path):
    assert tx40.rate_hz == 200.0 and tx40.robot == "tx40"
    assert set(tx40.streams) == {"q", "qd", "qdd", "tau"}
    assert tx40.time[0] < 0.1 and 7.3 < tx40.time[-1] < 8.0  # README: moves for ~7.4 s
    save_log(tx40, tmp_path / "tx40.h5")
    back = load_log(tmp_path / "tx40.h5")
    np.testing.assert_array_equal(back.streams["tau"].data, tx40.streams["tau"].data)


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


def test_tiago_log_window_and_streams(tiago):
    assert tiago.rate_hz == 100.0 and tiago.robot == "tiago"
    assert tiago.streams["q"].names == TIAGO_JOINTS
    assert tiago.streams["tau"].names == TIAGO_JOINTS[:5]  # wrist efforts left out
    # the README's excitation (rows 921-6791, 9.2-67.9 s) lies inside the detected window
    assert 5.0 < tiago.time[0] < 9.2 and 67.9 < tiago.time[-1] < 70.0
    np.testing.assert_allclose(np.diff(tiago.time), 0.01, atol=1e-9)
    # the README's rows 921-6791, as the benches cut them out of the log
    start, stop = np.searchsorted(tiago.time, [9.2, 67.9])
    readme = tiago.slice(int(start), int(stop))
    assert readme.time[0] >= 9.2 and readme.time[-1] < 67.9
    # the window is where a joint moves: the log's own qd finds the same one again
    assert excitation_window(tiago.streams["qd"].data, 100.0) == (0, tiago.n_samples)


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


def test_bundled_real_robots_load():
    tx = load_robot(REPO / "robots" / "tx40")
    assert tx.joint_names == tuple(f"joint_{i}" for i in range(1, 7))
    ti = load_robot(REPO / "robots" / "tiago")
    assert set(ti.joint_names) == set(TIAGO_JOINTS)
    data = ti.model.createData()
    pin.computeSubtreeMasses(ti.model, data)
    assert data.mass[ti.model.getJointId("torso_lift_joint")] == pytest.approx(18.5, abs=0.1)


@pytest.mark.skipif(not (RAW / "tx40").is_dir() or not (RAW / "tiago").is_dir(),
                    reason=f"no raw recordings at {RAW}")
@pytest.mark.parametrize("name, files", [("tx40", ["pos_read_data.csv", "curr_data.csv"]),
                                         ("tiago", ["tiago_position.csv", "tiago_effort.csv"])])
def test_shipped_logs_are_what_the_maps_make_of_the_recordings(name, files):
    """`make real-data` remakes sample_data/real: the committed logs match the import of the raw files."""
    made = import_log([RAW / name / f for f in files], load_map(SAMPLE / f"{name}.map.yaml")).log
    shipped = load_log(SAMPLE / f"{name}.h5")
    np.testing.assert_array_equal(made.time, shipped.time)
    assert made.robot == shipped.robot == name and made.rate_hz == shipped.rate_hz
    for key, stream in shipped.streams.items():
        assert made.streams[key].names == stream.names
        np.testing.assert_array_equal(made.streams[key].data, stream.data)
