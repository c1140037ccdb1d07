"""Static poses are cut against the pots' noise, not a fraction of their range (issue #32 item 3):
20 poses of 50 samples are 20 poses (the 1 %-of-range rule made 337 of them, since pot noise
exceeds it), snapshots are one pose a sample, a moving session is not static poses, and
leave-one-pose-out holds out every sample of a pose."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import synth

import diegocal.stac.pose_cv as stac_module
from diegocal.errors import FitError
from diegocal.robot import load_robot
from diegocal.sim.static_poses import StaticPoseOptions, simulate_static_poses
from diegocal.stac.pose_cv import leave_one_pose_out
from diegocal.stac.static import find_poses, pot_noise, static_poses

EXAMPLE = Path(__file__).parents[2] / "docs" / "example_robot"


@pytest.fixture(scope="module")
def example_robot():
    return load_robot(EXAMPLE)


def _truth_poses(log) -> np.ndarray:
    return log.truth.signals["pose"].data[:, 0].astype(int)


@pytest.mark.parametrize("samples", [50, 3, 1])
def test_poses_are_cut_at_the_holds(example_robot, samples):
    log = simulate_static_poses(example_robot, StaticPoseOptions(n_poses=20, samples=samples), np.random.default_rng(4))
    poses = find_poses(log)
    assert np.array_equal(poses, _truth_poses(log))
    assert np.array_equal(static_poses(log), poses)


def test_pot_noise_is_the_pots_noise(example_robot):
    log = simulate_static_poses(example_robot, StaticPoseOptions(n_poses=20, samples=50), np.random.default_rng(5))
    assert np.allclose(pot_noise(log.streams["pots"].data), 0.005, rtol=0.15)  # the simulator's pot_noise


def test_a_moving_session_is_not_static_poses(tree_robot):
    log = synth.simulate(tree_robot, 300, seed=6)
    assert static_poses(log) is None
    with pytest.raises(FitError, match="static poses"):
        leave_one_pose_out(log, tree_robot)


def test_leave_one_pose_out_holds_out_every_sample_of_a_pose(example_robot, monkeypatch):
    log = simulate_static_poses(example_robot, StaticPoseOptions(n_poses=6, samples=20), np.random.default_rng(7))
    seen = []
    fit = stac_module.calibrate

    def recording(data, robot, options=None):
        seen.append(data.n_samples)
        return fit(data, robot, options)

    monkeypatch.setattr(stac_module, "calibrate", recording)
    cv = leave_one_pose_out(log, example_robot)
    assert list(cv.pose) == list(range(6)) and list(cv.samples) == [20] * 6
    assert seen == [100] * 6 and np.all(np.isfinite(cv.error))


def test_snapshots_with_a_joint_held_at_a_few_values_are_one_pose_a_sample(tmp_path):
    """Chosen poses (``diegocal poses``) or a lab's list often hold a joint at a few values in
    turn (a torso at zero, a joint at its limits): that encoder has no sample-to-sample scale, and
    the log was read as one held pose (a Panda's 7 encoders, 30 snapshots, joint 1 at two values)."""
    gen = pytest.importorskip("experiments.static_geometry_generator")
    if not (gen.SHARE / gen.ROBOTS["panda"][0]).is_file():
        pytest.skip("example-robot-data is not installed")
    session = gen.Session("panda", 30, 1, seed=5, hardware_seed=5)
    q = gen.candidate_poses(session, 30, seed=6)
    q[:, 0] = np.where(np.arange(30) % 6 < 4, q[:, 0].min(), q[:, 0].max())
    _, log = gen.simulate(tmp_path, session, q=q)
    assert np.array_equal(static_poses(log), np.arange(30))
