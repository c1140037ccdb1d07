"""sensors.yaml and robot-directory validation: each bad entry raises RobotConfigError, on one
line, naming the entry (DESIGN.md: bad input gives one clear error line)."""

from __future__ import annotations

import numpy as np
import pytest

from diegocal.errors import RobotConfigError
from diegocal.robot import load_robot, parse_sensors


def _set(path, value):
    """A mutation setting ``sensors[path[0]][path[1]]...`` to ``value``."""

    def mutate(s):
        target = s
        for key in path[:-1]:
            target = target[key]
        target[path[-1]] = value

    return mutate


def _delete(path):
    def mutate(s):
        target = s
        for key in path[:-1]:
            target = target[key]
        del target[path[-1]]

    return mutate


def _append(key, index):
    def mutate(s):
        s[key].append(dict(s[key][index]))

    return mutate


# (id, mutation, substrings the one-line message must contain)
BAD_ENTRIES = [
    (
        "unknown_kind",
        _set(("pots", 1, "kind"), "magnetic"),
        ["pots[1] (j2_pot)", "unknown kind 'magnetic'"],
    ),
    ("missing_kind", _delete(("pots", 1, "kind")), ["pots[1] (j2_pot)", "unknown kind None"]),
    (
        "linear_one_anchor",
        _set(("pots", 3, "anchors"), [{"link": "l0", "xyz": [0, 0, 0]}]),
        ["pots[3] (lin_up)", "two anchors"],
    ),
    (
        "linear_anchor_no_link",
        _set(("pots", 3, "anchors", 1), {"xyz": [0, 0, 0]}),
        ["lin_up", "anchors[1]", "link"],
    ),
    ("linear_same_link", _set(("pots", 3, "anchors", 1, "link"), "l0"), ["lin_up", "both anchors"]),
    (
        "unknown_joint_rotary",
        _set(("pots", 1, "joint"), "nope"),
        ["pot 'j2_pot'", "no joint 'nope'"],
    ),
    (
        "unknown_joint_tendon",
        _set(("pots", 2, "moment_arms"), {"j2": 0.01, "nope": 0.02}),
        ["pot 'tendon'", "'nope'"],
    ),
    ("unknown_joint_encoder", _set(("pots", 0, "joint"), "nope"), ["pot 'slide_enc'", "'nope'"]),
    (
        "unknown_anchor_link",
        _set(("pots", 4, "anchors", 0, "link"), "nowhere"),
        ["pot 'lin_base'", "no link 'nowhere'"],
    ),
    (
        "unknown_marker_link",
        _set(("markers", 1, "link"), "nowhere"),
        ["marker 'm_arm'", "no link 'nowhere'"],
    ),
    ("duplicate_pot", _append("pots", 1), ["pots[5] (j2_pot)", "duplicate name"]),
    ("duplicate_marker", _append("markers", 0), ["markers[3] (m_l0)", "duplicate name"]),
    (
        "non_numeric_gain",
        _set(("pots", 1, "gain"), "abc"),
        ["pots[1] (j2_pot)", "'gain' must be a number"],
    ),
    (
        "non_numeric_bias",
        _set(("pots", 2, "bias"), [1, 2]),
        ["pots[2] (tendon)", "'bias' must be a number"],
    ),
    ("nan_bias", _set(("pots", 1, "bias"), float("nan")), ["pots[1] (j2_pot)", "finite"]),
    ("zero_gain", _set(("pots", 1, "gain"), 0.0), ["pots[1] (j2_pot)", "non-zero"]),
    (
        "non_numeric_arm",
        _set(("pots", 2, "moment_arms", "j3"), "long"),
        ["pots[2] (tendon)", "'j3' must be a number"],
    ),
    ("empty_arms", _set(("pots", 2, "moment_arms"), {}), ["pots[2] (tendon)", "moment_arms"]),
    ("rotary_no_joint", _delete(("pots", 1, "joint")), ["pots[1] (j2_pot)", "needs 'joint'"]),
    ("encoder_gain_not_one", _set(("pots", 0, "gain"), 2.0), ["pots[0] (slide_enc)", "fixed at 1"]),
    (
        "encoder_gain_text",
        _set(("pots", 0, "gain"), "one"),
        ["pots[0] (slide_enc)", "'gain' must be a number"],
    ),
    ("missing_base_link", _delete(("base_link",)), ["'base_link'", "required"]),
    ("unknown_base_link", _set(("base_link",), "nowhere"), ["base_link 'nowhere'"]),
    ("marker_xyz_two", _set(("markers", 1, "xyz"), [0.1, 0.2]), ["markers[1] (m_arm)", "'xyz'"]),
    ("marker_no_link", _delete(("markers", 2, "link")), ["markers[2] (m_hand)", "needs 'link'"]),
    ("entry_no_name", _delete(("pots", 0, "name")), ["pots[0]", "missing 'name'"]),
    ("entry_not_mapping", _set(("markers", 0), "m_l0"), ["markers[0]", "expected a mapping"]),
    ("pots_not_list", _set(("pots",), {"a": 1}), ["'pots' must be a list"]),
    (
        "chamber_unknown_joint",
        _set(("chambers", 0, "joint"), "nope"),
        ["chamber 'j2.flex'", "'nope'"],
    ),
    (
        "chamber_unknown_volume",
        _set(("chambers", 0, "volume_sensor"), "nope"),
        ["chamber 'j2.flex'", "volume_sensor 'nope'"],
    ),
    (
        "chamber_supply_below_room",
        _set(("chambers", 0, "supply"), 50.0),
        ["chambers[0] (j2.flex)", "supply > room"],
    ),
    (
        "chamber_no_room",
        _delete(("chambers", 0, "room")),
        ["chambers[0] (j2.flex)", "missing 'room'"],
    ),
]


def test_tiny_config_is_valid(robot_dir, tiny_sensors):
    """The baseline every mutation below starts from loads without error."""
    robot = load_robot(robot_dir(tiny_sensors))
    assert robot.sensors.pot_names == ("slide_enc", "j2_pot", "tendon", "lin_up", "lin_base")


@pytest.mark.parametrize(
    ("mutate", "expected"), [c[1:] for c in BAD_ENTRIES], ids=[c[0] for c in BAD_ENTRIES]
)
def test_bad_entry_raises_naming_it(mutate, expected, robot_dir, tiny_sensors):
    mutate(tiny_sensors)
    with pytest.raises(RobotConfigError) as info:
        load_robot(robot_dir(tiny_sensors))
    message = str(info.value)
    assert "\n" not in message
    for part in expected:
        assert part in message


def test_top_level_not_mapping():
    with pytest.raises(RobotConfigError, match="mapping at the top level"):
        parse_sensors(["pots"], source="x.yaml")


def test_robot_directory_problems(tmp_path, robot_dir, tiny_sensors):
    with pytest.raises(RobotConfigError, match="robot directory not found"):
        load_robot(tmp_path / "absent")
    (tmp_path / "empty").mkdir()
    with pytest.raises(RobotConfigError, match="no sensors.yaml"):
        load_robot(tmp_path / "empty")
    tiny_sensors["urdf"] = "other.urdf"
    with pytest.raises(RobotConfigError, match="URDF 'other.urdf' not found"):
        load_robot(robot_dir(tiny_sensors))


def test_unloadable_urdf(robot_dir, tiny_sensors):
    with pytest.raises(RobotConfigError, match="Pinocchio cannot load it"):
        load_robot(robot_dir(tiny_sensors, urdf="<robot name='x'><link name='a'/><joint"))


def test_continuous_joint_becomes_revolute(robot_dir, tiny_sensors, tiny_urdf):
    """A continuous joint (Pinocchio: two position coordinates) loads as revolute within ±π."""
    urdf = tiny_urdf.replace('name="j3" type="revolute"', 'name="j3" type="continuous"')
    assert urdf != tiny_urdf
    robot = load_robot(robot_dir(tiny_sensors, urdf=urdf))
    k = robot.joint_index("j3")
    assert robot.model.nq == robot.model.nv == robot.n_joints
    assert (robot.lower[k], robot.upper[k]) == pytest.approx((-np.pi, np.pi))


def test_locked_entry_checked(robot_dir, tiny_sensors):
    tiny_sensors["locked"] = {"j3": "up"}
    with pytest.raises(RobotConfigError, match=r"locked\[j3\] must be a number"):
        load_robot(robot_dir(tiny_sensors))
    tiny_sensors["locked"] = {"nope": 0.1}
    with pytest.raises(RobotConfigError, match="locked joint 'nope' is not a joint"):
        load_robot(robot_dir(tiny_sensors))
    tiny_sensors["locked"] = {"j3": 0.1}  # a pot (the tendon) reads j3
    with pytest.raises(RobotConfigError, match="joint 'j3' is locked"):
        load_robot(robot_dir(tiny_sensors))
