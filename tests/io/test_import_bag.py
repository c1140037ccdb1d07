"""`diegocal import` of ROS bags (written here with rosbags): ROS 1 .bag, ROS 2 .db3 and .mcap."""

import numpy as np
import pytest

from diegocal.errors import LogFormatError
from diegocal.io.importers import MapError, import_log, parse_map
from tests.io.labfiles import EPOCH_NS, write_bag, write_c3d

NAMES = ["joint1", "joint2", "joint3"]
T = 25


@pytest.fixture
def signals():
    rng = np.random.default_rng(3)
    return np.arange(T) * 0.004, *(rng.normal(size=(T, 3)) for _ in range(3)), rng.normal(size=(T, 6))


def _bag(tmp_path, kind, signals, **kw):
    t, pos, vel, eff, wrench = signals
    if kind == "ros1":
        return write_bag(tmp_path / "run.bag", "ros1", NAMES, t, pos, vel, eff, extra=wrench, **kw)
    return write_bag(tmp_path / "run", kind, NAMES, t, pos, vel, eff, extra=wrench, **kw)


@pytest.mark.parametrize("kind", ["ros1", "db3", "mcap"])
def test_joint_states_become_q_qd_tau(tmp_path, kind, signals):
    t, pos, vel, eff, _ = signals
    folder_or_file = _bag(tmp_path, kind, signals, stamp_offset=0.002)
    paths = [folder_or_file] if kind == "ros1" else [folder_or_file, next(folder_or_file.glob(f"*.{kind}"))]
    for path in paths:  # a ROS 2 bag as its folder and as the bare storage file
        result = import_log([path])
        log = result.log
        assert list(log.streams) == ["q", "qd", "tau"] and log.streams["q"].names == tuple(NAMES)
        np.testing.assert_array_equal(log.streams["q"].data, pos)
        np.testing.assert_array_equal(log.streams["qd"].data, vel)
        np.testing.assert_array_equal(log.streams["tau"].data, eff)
        np.testing.assert_allclose(log.time - EPOCH_NS * 1e-9, t, atol=1e-6)  # header stamps
        assert any("topics not imported: /wrench" in n for n in result.notes)
    received = import_log([path], parse_map({"sources": {"run": {"stamp": "receive", "zero_time": True}}})).log
    np.testing.assert_allclose(received.time, t, atol=1e-12)  # receive times, from the first message


def test_other_topics_by_mapping_and_close_matches(tmp_path, signals):
    *_, wrench = signals
    path = _bag(tmp_path, "mcap", signals)
    mapping = parse_map({"streams": {
        "q": {"table": "/joint_states", "columns": {"joint2": "elbow"}},
        "tau": {"table": "/wrench", "columns": {"wrench.force.z": "elbow", "wrench.torque.x": "wrist"}}}})
    log = import_log([path], mapping).log
    np.testing.assert_array_equal(log.streams["q"].data[:, 0], signals[1][:, 1])  # position.joint2
    np.testing.assert_array_equal(log.streams["tau"].data, wrench[:, [2, 3]])
    with pytest.raises(MapError, match="no table '/wrenchs' .* did you mean '/wrench'"):
        import_log([path], parse_map({"streams": {"tau": {"table": "/wrenchs", "columns": ["x"]}}}))
    with pytest.raises(MapError, match="no column 'wrench.force.w' .* did you mean 'wrench.force.[xyz]'"):
        import_log([path], parse_map({"streams": {"tau": {"table": "/wrench", "columns": ["wrench.force.w"]}}}))


def test_a_driver_without_velocities_gives_no_qd(tmp_path, signals):
    t, pos, _, eff, _ = signals
    path = write_bag(tmp_path / "novel.bag", "ros1", NAMES, t, pos, None, eff)
    assert list(import_log([path]).log.streams) == ["q", "tau"]


def test_bag_and_mocap_meet_on_the_mocap_clock(tmp_path):
    # joint states at 250 Hz on the ROS clock; mocap at 100 Hz from its own zero, 0.5 s after the bag began
    t = np.arange(500) * 0.004
    q = np.column_stack([2 * t, -t, t + 1])
    bag = write_bag(tmp_path / "arm.bag", "ros1", NAMES, t, q)
    c3d = write_c3d(tmp_path / "mocap.c3d", ["M"], np.ones((100, 1, 3)), rate=100.0)
    mapping = parse_map({"sources": {"arm": {"file": "arm.bag", "zero_time": True, "time_offset": -0.5},
                                     "mocap": {"file": "mocap.c3d"}}})
    log = import_log([bag, c3d], mapping).log
    np.testing.assert_allclose(log.time, np.arange(100) / 100.0)
    bag_time = log.time + 0.5  # the bag's clock, from its first message
    np.testing.assert_allclose(log.streams["q"].data, np.column_stack([2 * bag_time, -bag_time, bag_time + 1]),
                               atol=1e-9)


def test_a_broken_bag_is_one_line(tmp_path):
    (tmp_path / "broken.bag").write_bytes(b"#ROSBAG V2.0\n" + b"\x00" * 64)
    with pytest.raises(LogFormatError, match="broken.bag: not a readable ROS bag") as err:
        import_log([tmp_path / "broken.bag"])
    assert "\n" not in str(err.value)
    (tmp_path / "empty.mcap").write_bytes(b"")
    with pytest.raises(LogFormatError, match="empty.mcap: not a readable ROS bag"):
        import_log([tmp_path / "empty.mcap"])


def test_jittered_stamps_filtered_and_derived_on_the_bag_own_clock(tmp_path):
    rng = np.random.default_rng(5)
    t = np.cumsum(rng.uniform(0.008, 0.012, 400))  # ~100 Hz with jitter, as drivers publish
    q = np.column_stack([np.sin(t), np.cos(2 * t), t])
    path = write_bag(tmp_path / "j.bag", "ros1", NAMES, t, q, None, 2 * q)
    result = import_log([path], parse_map({"filter": {"cutoff_hz": 5}, "derive": ["qd"],
                                           "sources": {"j": {"zero_time": True}}}))
    log = result.log
    assert "j.bag /joint_states's time stamps" in result.clock  # not a resampling grid
    np.testing.assert_allclose(log.time, (t - t[0])[: log.n_samples], atol=1e-9)
    # the filtering grid ends up to one step before the last stamp, the clock one stamp before that
    assert log.time[-1] >= t[-1] - t[0] - 0.01 - 0.012
    inner = slice(50, -50)
    np.testing.assert_allclose(log.streams["qd"].data[inner], np.column_stack(
        [np.cos(t), -2 * np.sin(2 * t), np.ones_like(t)])[: log.n_samples][inner], atol=5e-3)
    # filtered on a uniform grid at the median rate (1 / 9.9 ms here: 101 Hz), then read at the stamps
    assert any("uniform 101 Hz grid" in n for n in result.notes), result.notes


@pytest.mark.parametrize("kind", ["ros1", "mcap"])
def test_zero_time_starts_the_log_at_its_first_header_stamp(tmp_path, kind, signals):
    # the case: received 2.3 ms after their header stamps, zeroed on the first receive time,
    # the messages started the log at -2.3 ms
    t = signals[0]
    path = _bag(tmp_path, kind, signals, stamp_offset=0.0023)
    log = import_log([path], parse_map({"sources": {"run": {"zero_time": True}}})).log
    assert log.time[0] == 0.0
    np.testing.assert_allclose(log.time, t, atol=1e-12)


def test_a_truncated_ros1_bag_says_to_reindex_it(tmp_path, signals):
    full = _bag(tmp_path, "ros1", signals).read_bytes()
    for n in (len(full) // 2, len(full) - 100):
        (tmp_path / "cut.bag").write_bytes(full[:n])
        with pytest.raises(LogFormatError, match=r"cut.bag: not a readable ROS bag .*truncated or never closed: "
                                                 r"rebuild its index with `rosbag reindex cut.bag`") as err:
            import_log([tmp_path / "cut.bag"])
        assert "\n" not in str(err.value)


@pytest.mark.parametrize("kind", ["ros1", "db3"])
def test_arm_and_gripper_publishers_merge_by_joint_name(tmp_path, kind):
    # an arm driver at 100 Hz and a gripper driver at 20 Hz, 3 ms later, both on /joint_states
    t = np.arange(300) * 0.01
    arm = np.column_stack([np.sin(t), np.cos(t), t])
    tg = 0.003 + np.arange(58) * 0.05
    grip = np.column_stack([0.01 * tg, -0.02 * tg])  # straight lines: read exactly between samples
    path = write_bag(tmp_path / ("run.bag" if kind == "ros1" else "run"), kind, NAMES, t, arm, None, 2 * arm,
                     publishers=[(["finger_l", "finger_r"], tg, grip, 3 * grip)])
    result = import_log([path], parse_map({"sources": {"run": {"zero_time": True}}}))
    log = result.log
    assert log.streams["q"].names == (*NAMES, "finger_l", "finger_r")
    inside = (t >= tg[0]) & (t <= tg[-1])  # the span both publishers cover, on the arm's stamps
    np.testing.assert_allclose(log.time, t[inside], atol=1e-12)
    np.testing.assert_array_equal(log.streams["q"].data[:, :3], arm[inside])
    np.testing.assert_allclose(log.streams["q"].data[:, 3:], np.column_stack([0.01 * t, -0.02 * t])[inside],
                               atol=1e-12)
    np.testing.assert_allclose(log.streams["tau"].data[:, 3:], 3 * log.streams["q"].data[:, 3:], atol=1e-12)
    assert any("2 publishers (joint1, joint2, joint3; finger_l, finger_r) merged by joint name" in n
               for n in result.notes), result.notes
    both = write_bag(tmp_path / "both.bag", "ros1", NAMES, t, arm, publishers=[(["joint3", "x"], tg, grip, None)])
    with pytest.raises(LogFormatError, match="two publishers name joint 'joint3'"):
        import_log([both])
