"""STAC benchmarks: q-phase schedules (thesis §2.6.1, Fig. 2.6) and the thesis-size run.

Part 1 compares, on the tendon finger (200 frames as in §2.6.1, seeds from sensors.yaml,
markers at link origins), the schedules of :func:`diegocal.stac.stac.calibrate`:
LM-batch, LM-iter and BFGS (plain alternation, as in the thesis) and LM-iter with the joint
Schur step (the default). Per iteration: cost, wall time and mean relative parameter error
against the simulator truth (gains and marker positions, gauge-free entries).

Part 2 runs STAC on diego at thesis size (100 Hz x 250 s = 25,000 frames, 38 joints,
24 markers) and the classical σp = 0 method on the same data, printing wall time, peak
resident memory (resource.getrusage) and where STAC's time goes.

    .venv/bin/python bench/bench_stac.py [--frames 25000] [--skip-full] [--skip-schedules]
"""

from __future__ import annotations

import argparse
import cProfile
import io
import pstats
import resource
import time
from dataclasses import replace

import numpy as np

from diegocal.robot import load_robot, resolve_robot_dir
from diegocal.sim.kinematics import KinematicsOptions, simulate_kinematics
from diegocal.stac.calibration import Calibration
from diegocal.stac.model import Observation
from diegocal.stac.result import StacOptions
from diegocal.stac.stac import calibrate


def rel_error(cal: Calibration, truth: Calibration, gauge_free_markers: np.ndarray) -> float:
    """Mean relative error of gains and (gauge-free) marker positions (Fig. 2.6b)."""
    g = np.abs(cal.gain / truth.gain - 1)
    scale = np.linalg.norm(truth.marker_xyz, axis=1).mean()
    d = np.linalg.norm(cal.marker_xyz - truth.marker_xyz, axis=1)[gauge_free_markers] / scale
    return float(np.mean(np.concatenate([g, d])))


def gauge_free_markers(robot, log) -> np.ndarray:
    obs = Observation(log, robot)
    obs.check_observable()
    fixed = {obs.pot_specs[j].joint for j in np.flatnonzero(obs.fixed_bias)}
    out = []
    for m in robot.sensors.markers:
        j = robot.model.frames[robot.frame_id(m.link)].parentJoint
        out.append(not (j > 0 and robot.joint_names[j - 1] in fixed))
    return np.array(out)


def schedules(seed: int = 0) -> None:
    robot = load_robot(resolve_robot_dir("finger", None))
    # 200 well-spread configurations as in §2.6.1 ("200 random joint angles"): 100 s of PID
    # motion sampled at 2 Hz (2 s at 100 Hz would barely move the joints)
    opts = KinematicsOptions(duration=100.0, rate_hz=2.0, occlusion=0.0)
    log = simulate_kinematics(robot, opts, np.random.default_rng(seed))
    truth = Calibration.from_dict(log.truth.params)
    free = gauge_free_markers(robot, log)
    data = log.without_truth()
    variants = {
        "LM-batch": StacOptions(schedule="lm-batch", joint=False),
        "LM-iter": StacOptions(schedule="lm-iter", joint=False),
        "BFGS": StacOptions(schedule="bfgs", joint=False),
        "LM-iter + Schur (default)": StacOptions(),
    }
    print(f"== q-phase schedules (thesis §2.6.1 / Fig. 2.6): finger, {log.n_samples} frames, seed {seed}")
    print(f"{'schedule':<28}{'iter':>5}{'time s':>9}{'cost':>14}{'rel. err':>10}")
    summary = []
    for name, o in variants.items():
        rows = []
        t0 = time.perf_counter()

        def cb(it, cal, rows=rows, t0=t0):
            rows.append((it, time.perf_counter() - t0, rel_error(cal, truth, free)))

        res = calibrate(data, robot, replace(o, max_iterations=60, on_iteration=cb))
        for (it, t, err), h in zip(rows, res.history, strict=True):
            if it <= 5 or it % 10 == 0 or it == len(rows):
                print(f"{name:<28}{it:>5}{t:>9.2f}{h.cost:>14.1f}{err:>10.4f}")
        summary.append((name, len(rows), rows[-1][1], res.history[-1].cost, rows[-1][2]))
    print(f"\n{'schedule':<28}{'iters':>6}{'time s':>9}{'final cost':>14}{'rel. err':>10}")
    for name, n, t, c, e in summary:
        print(f"{name:<28}{n:>6}{t:>9.2f}{c:>14.1f}{e:>10.4f}")


def full(frames: int, seed: int = 0) -> None:
    robot = load_robot(resolve_robot_dir("diego", None))
    opts = KinematicsOptions(duration=frames / 100.0, rate_hz=100.0)
    log = simulate_kinematics(robot, opts, np.random.default_rng(seed))
    truth = Calibration.from_dict(log.truth.params)
    data = log.without_truth()
    print(
        f"\n== thesis size: diego, {log.n_samples} frames, {robot.n_joints} joints, "
        f"{len(robot.sensors.markers)} markers, occlusion {opts.occlusion:.0%}"
    )
    print(f"{'method':<12}{'wall s':>9}{'peak RSS MiB':>14}{'iters':>7}{'gain rel err':>14}{'q RMSE rad':>12}")
    q_true = log.truth.signals["q"].data
    obs = Observation(data, robot)
    obs.check_observable()
    gauge = {obs.pot_specs[j].joint for j in np.flatnonzero(obs.fixed_bias)}
    free_q = [i for i, n in enumerate(robot.joint_names) if n not in gauge]
    prof = cProfile.Profile()
    for name in ("stac", "classical"):
        t0 = time.perf_counter()
        if name == "stac":
            prof.enable()
            res = calibrate(data, robot, StacOptions(max_iterations=30))
            prof.disable()
        else:
            from diegocal.stac.classical import calibrate_classical

            res = calibrate_classical(data, robot, StacOptions(), nonlinear="constrain")
        wall = time.perf_counter() - t0
        rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
        cal = res.calibration
        gerr = float(np.median(np.abs(cal.gain / truth.gain - 1)))
        rmse = float(np.sqrt(np.mean((res.q - q_true)[:, free_q] ** 2)))  # gauge joints excluded
        print(f"{name:<12}{wall:>9.1f}{rss:>14.0f}{cal.fit.iterations:>7}{gerr:>14.4f}{rmse:>12.4f}")
    buf = io.StringIO()
    pstats.Stats(prof, stream=buf).sort_stats("cumulative").print_stats(
        "(stac/(stac|qphase|pphase|joint_step|model)|robot/batch).py", 18
    )
    print("\nwhere STAC's time goes (cumulative seconds):")
    print("\n".join(line for line in buf.getvalue().splitlines() if "stac/" in line or "cumtime" in line))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=25000)
    ap.add_argument("--skip-full", action="store_true")
    ap.add_argument("--skip-schedules", action="store_true")
    args = ap.parse_args()
    if not args.skip_schedules:
        schedules()
    if not args.skip_full:
        full(args.frames)


if __name__ == "__main__":
    main()
