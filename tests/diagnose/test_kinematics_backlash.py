"""A pot's dead band fitted as ``diagnose`` fits it, against the simulator's
(diegocal/stac/terms.py: the band's direction is read through a smoother)."""

from __future__ import annotations

import numpy as np
import pytest

from diegocal.diagnose.kinematics import KinematicsAdapter
from diegocal.evaluate import split_blocks
from diegocal.robot import load_robot
from diegocal.sim.effects import EffectRequest
from diegocal.sim.kinematics import KinematicsOptions, backlash, simulate_kinematics
from diegocal.stac.terms import pot_columns
from diegocal.terms import make_term


def test_a_smooth_reading_gives_the_play_operators_direction():
    """On a noise-free smooth reading the smoother changes nothing: the column is the play's."""
    t = np.arange(3000) / 100.0
    x = 0.3 * np.sin(0.7 * t) + 0.2 * np.sin(1.9 * t + 1.0)
    term = make_term("backlash", "p", extra={"width": 0.02})
    assert np.allclose(pot_columns(term, x)[:, 0] * 0.01, backlash(x, 0.02) - x, atol=1e-4)


def test_a_wrist_dead_band_covers_the_truth(tmp_path):
    """UR5 of experiments/kinematics_generator.py (three markers a link), the project's simulator
    hiding a dead band on wrist_3's pot, which alone fixes its joint (its markers lie near the
    axis): fitted with the true band, half the band within 2 SE and 10 % of the truth. With the
    direction read from the model's reading as it is, whose noise is the pot's own there:
    1.27e-2 ± 1.1e-3 V against 1.61e-2 (3.0 SE short)."""
    from experiments.kinematics_generator import robot_dir

    robot = load_robot(robot_dir(tmp_path, "ur5"))
    effect = EffectRequest("backlash", "wrist_3_joint_pot", None)
    log = simulate_kinematics(robot, KinematicsOptions(duration=30.0, effects=(effect,)), np.random.default_rng(5))
    width = log.truth.effects[0]["values"]["width_reading"]
    train = split_blocks(log.n_samples, 10).mask("train")
    term = make_term("backlash", "wrist_3_joint_pot", extra={"width": width})
    got = KinematicsAdapter(log, robot).fit((term,), train).terms[0]
    assert abs(got.values[0] - width / 2) <= 2 * got.stderrs[0]
    assert got.values[0] == pytest.approx(width / 2, rel=0.1)
