"""A kinematic sensor fault no cause of the vocabulary describes is called `unexplained`, never a
wrong name (issue #31, item 1): shapes of experiments/kinematics_oov.py, written apart from the
simulator, added to a clean finger session."""

from __future__ import annotations

import numpy as np
import pytest

from diegocal.diagnose import DiagnoseOptions, diagnose
from experiments.kinematics_oov import MARKER_NOISE, POT_NOISE, add_shape, clean_session


def test_the_shapes_are_added_to_one_channel_at_their_size():
    clean, *_ = clean_session(5)
    for shape in ("worn_track", "runout", "warm_up", "crosstalk"):
        log, _, channel, ratio = add_shape(shape, 5)
        d = log.streams["pots"].data - clean.streams["pots"].data
        i = log.streams["pots"].names.index(channel)
        assert np.abs(np.delete(d, i, axis=1)).max() == 0.0  # one pot only
        size = np.sqrt(np.mean(d[:, i] ** 2)) if shape == "crosstalk" else np.abs(d[:, i]).max()
        assert abs(size / POT_NOISE - ratio) < 0.05 * ratio, shape
    log, _, marker, ratio = add_shape("wobble", 5)
    m = log.streams["markers"].names.index(marker)
    d = log.streams["markers"].data[:, m] - clean.streams["markers"].data[:, m]
    assert abs(np.sqrt(np.nanmean(d**2)) / MARKER_NOISE - ratio) < 0.05 * ratio  # RMS per axis


def test_a_worn_pot_track_is_unexplained_on_its_pot_not_a_transfer_curve():
    """A dip a twentieth of the pot's range wide: the cubic transfer curve explains little of what
    a flexible function of the reading does, so the pot is ``unexplained`` (no name at all)."""
    log, robot, channel, _ = add_shape("worn_track", 5)
    d = diagnose(log, robot, DiagnoseOptions(domain="kinematics"))
    assert [(f.cause, f.channel) for f in d.findings] == [("unexplained", channel)]
    region = d.findings[0].term.region
    assert region.variable == f"p.{channel}"


@pytest.mark.parametrize(
    "shape, seed, stand_in",
    [
        ("runout", 20262130, "sensor_nonlinearity:ulnar_int"),  # five periods, 8.9 × the noise
        ("crosstalk", 20264142, "backlash:ulnar_int"),  # 6.2 × the noise
    ],
)
def test_a_fault_misread_as_the_next_pots_term_is_unexplained_on_the_faulty_pot(shape, seed, stand_in):
    """A runout on mcp_abd, or another pot's signal picked up by it: the tracking moves part of it
    to a neighbouring pot, where a term of that pot (its curve, its dead band) removes part of the
    validation error. A flexible model of mcp_abd (its curve; its mixing row, its reading plus a
    linear function of the chain's joint angles) removes more, so mcp_abd is ``unexplained``; the
    finding says which term stood in."""
    log, robot, channel, _ = add_shape(shape, seed)
    assert channel == "mcp_abd"
    d = diagnose(log, robot, DiagnoseOptions(domain="kinematics"))
    assert [(f.cause, f.channel) for f in d.findings] == [("unexplained", "mcp_abd")]
    assert d.findings[0].evidence["stand_in"]["term"] == stand_in


def test_a_terms_neighbours_are_the_pots_on_a_chain_through_its_joints():
    """The pots whose flexible models are offered beside a term: beside a pot's, every other pot of
    the finger (one chain), and on Diego San beside the left elbow's the torso's and the left arm's
    pots, none of a leg or the other arm; beside a link offset of the left knee, the left leg's."""
    from diegocal.diagnose.kinematics_curves import neighbour_pots
    from diegocal.robot import load_robot, resolve_robot_dir
    from diegocal.sim.kinematics import KinematicsOptions, simulate_kinematics
    from diegocal.stac.model import Observation
    from diegocal.terms import Term

    def neighbours(robot_name, cause, channel):
        robot = load_robot(resolve_robot_dir(robot_name, None))
        log = simulate_kinematics(robot, KinematicsOptions(duration=1.0), np.random.default_rng(1))
        obs = Observation(log, robot, need=(), needed_by="test")
        near = neighbour_pots(obs, robot, Term(cause, channel, ()))
        return {obs.pot_names[i] for i in near}, set(obs.pot_names)

    near, pots = neighbours("finger", "backlash", "dip")
    assert near == pots - {"dip"}
    near, _ = neighbours("diego", "backlash", "l_elbow")
    arm = {"l_clavicle", "l_shoulder_pitch", "l_shoulder_roll", "l_shoulder_yaw", "l_wrist_yaw", "l_wrist_pitch"}
    assert {"torso_yaw", "chest_pitch", *arm} <= near
    assert not any(p.startswith("r_") or "hip" in p or "knee" in p for p in near), near
    near, _ = neighbours("diego", "link_offset", "l_knee")
    assert {"l_hip_yaw", "l_hip_roll", "l_hip_pitch", "l_knee", "l_toe"} <= near
    assert not any(p.startswith("r_") or "elbow" in p for p in near), near
