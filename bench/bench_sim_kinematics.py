"""Timing of the kinematics simulator on diego (38 joints, 38 pots, 24 markers), thesis §2.5.1.

    .venv/bin/python bench/bench_sim_kinematics.py [SECONDS]

Simulates SECONDS (default 250, i.e. 25,000 frames at 100 Hz, the thesis' session) and prints
the time of each stage. Reference method timed in the same run: the same marker positions
through the library's per-frame ``Robot.points`` loop (``predict_markers``), against the
simulator's batched ``base_points`` (one forward-kinematics pass per frame, numpy for the
points); the two must agree to 1e-12 m.
"""

from __future__ import annotations

import sys
import time

import numpy as np

from diegocal.robot import BUNDLED_ROBOTS, load_robot, pot_transmission, predict_markers
from diegocal.sim import KinematicsOptions, parse_effects, simulate_kinematics
from diegocal.sim.kinematics import joint_ranges, marker_positions, pid_trajectory
from diegocal.stac.calibration import Calibration


def timed(fn, repeats: int = 3):
    best, out = np.inf, None
    for _ in range(repeats):
        start = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - start)
    return best, out


def main(seconds: float = 250.0) -> None:
    robot = load_robot(BUNDLED_ROBOTS / "diego")
    opts = KinematicsOptions(duration=seconds)
    T = opts.n_samples
    rng = np.random.default_rng(0)
    lo, hi = joint_ranges(robot)
    t_traj, (q, _) = timed(lambda: pid_trajectory(lo, hi, T, 100.0, np.random.default_rng(0)))
    t_pots, _ = timed(lambda: pot_transmission(robot, q), 1)
    log = simulate_kinematics(robot, KinematicsOptions(duration=1.0), rng)
    truth = Calibration.from_dict(log.truth.params)
    t_batch, fast = timed(lambda: marker_positions(robot, q, truth), 1)
    t_ref, ref = timed(lambda: predict_markers(robot, q, truth.marker_xyz, truth.mocap_R,
                                               truth.mocap_T), 1)
    t_all, _ = timed(lambda: simulate_kinematics(robot, opts, np.random.default_rng(1)), 1)
    effects = parse_effects(["link_offset", "backlash", "sensor_nonlinearity", "time_offset",
                             "marker_slip"])
    t_eff, _ = timed(lambda: simulate_kinematics(
        robot, KinematicsOptions(duration=seconds, effects=effects), np.random.default_rng(1)), 1)
    rows = [
        ("PID trajectory (38 joints)", t_traj),
        ("pot transmission s(q) (library, 8 linear pots)", t_pots),
        ("markers, batched base_points (simulator)", t_batch),
        ("markers, Robot.points per frame (reference)", t_ref),
        ("simulate_kinematics, no effect", t_all),
        ("simulate_kinematics, all 5 effects", t_eff),
    ]
    print(f"diego, {T} frames ({seconds:g} s at 100 Hz)")
    print(f"{'stage':<50} {'seconds':>8} {'us/frame':>9}")
    for name, sec in rows:
        print(f"{name:<50} {sec:8.3f} {1e6 * sec / T:9.1f}")
    print(f"max |batched - reference| = {np.abs(fast - ref).max():.2e} m")


if __name__ == "__main__":
    main(float(sys.argv[1]) if len(sys.argv) > 1 else 250.0)
