"""STAC benchmarks: q-phase schedules (thesis §2.6.1, Fig. 2.6) and the thesis-size run.

Part 1 compares, on the tendon finger (200 frames as in §2.6.1, seeds from sensors.yaml,
markers at link origins), the schedules of STAC (:func:`diegocal.api.calibrate`, method stac):
LM-batch, LM-iter and BFGS (plain alternation, as in the thesis) and LM-iter with the joint
Schur step (the default). Per iteration: cost, wall time and mean relative parameter error
against the simulator truth (gains and marker positions, gauge-free entries).

Part 2 runs STAC on diego at thesis size (100 Hz x 250 s = 25,000 frames, 38 joints,
24 markers), with one and two worker threads, and the classical σp = 0 method on the same data,
printing wall and CPU time, peak resident memory (resource.getrusage: the process's peak so
far, so each row includes the rows above it), the load average, accuracy against the simulator
truth, and where STAC's time goes (per stage, and a CPU-time profile of a second run).

Part 3 checks that the coarse-to-fine schedule ends at the full-data optimum: the same log
(5,000 frames) calibrated with coarse_frames=0, differences in units of standard errors.

    .venv/bin/python bench/bench_stac.py [--frames 25000] [--skip-full] [--skip-schedules]
        [--skip-verify] [--skip-classical] [--verify-frames 5000]
"""

from __future__ import annotations

import argparse
import cProfile
import io
import os
import pstats
import resource
import time
from dataclasses import replace

import numpy as np

from diegocal.api import calibrate
from diegocal.robot import load_robot, resolve_robot_dir
from diegocal.sim.kinematics import KinematicsOptions, simulate_kinematics
from diegocal.stac.calibration import Calibration
from diegocal.stac.model import Observation
from diegocal.stac.result import StacOptions


def rel_error(cal: Calibration, truth: Calibration, gauge_free_markers: np.ndarray) -> float:
    """Mean relative error of gains and (gauge-free) marker positions (Fig. 2.6b)."""
    g = np.abs(cal.gain / truth.gain - 1)
    scale = np.linalg.norm(truth.marker_xyz, axis=1).mean()
    d = np.linalg.norm(cal.marker_xyz - truth.marker_xyz, axis=1)[gauge_free_markers] / scale
    return float(np.mean(np.concatenate([g, d])))


def gauge_free_markers(robot, log) -> np.ndarray:
    obs = Observation(log, robot)
    obs.check_observable()
    return obs.gauge_free_markers()


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

        res = calibrate(data, robot, options=replace(o, max_iterations=60, on_iteration=cb))
        for (it, t, err), h in zip(rows, res.history, strict=True):
            if it <= 5 or it % 10 == 0 or it == len(rows):
                print(f"{name:<28}{it:>5}{t:>9.2f}{h.cost:>14.1f}{err:>10.4f}")
        summary.append((name, len(rows), rows[-1][1], res.history[-1].cost, rows[-1][2]))
    print(f"\n{'schedule':<28}{'iters':>6}{'time s':>9}{'final cost':>14}{'rel. err':>10}")
    for name, n, t, c, e in summary:
        print(f"{name:<28}{n:>6}{t:>9.2f}{c:>14.1f}{e:>10.4f}")


def _diego(frames: int, seed: int):
    robot = load_robot(resolve_robot_dir("diego", None))
    opts = KinematicsOptions(duration=frames / 100.0, rate_hz=100.0)
    log = simulate_kinematics(robot, opts, np.random.default_rng(seed))
    return robot, log, opts


def _free_joints(robot, data) -> list[int]:
    """Joints whose zero is not a gauge freedom (their q RMSE is comparable to the truth)."""
    obs = Observation(data, robot)
    obs.check_observable()
    gauge = {obs.pot_specs[j].joint for j in np.flatnonzero(obs.fixed_bias)}
    return [i for i, n in enumerate(robot.joint_names) if n not in gauge]


def _bias_z(robot, data, cal, truth) -> float:
    """max |bias − truth| / SE over the estimated biases, against the gauge-equivalent truth: a pot
    whose bias is fixed at nominal shifts its joint's zero by δ = (b_true − b_nominal) / gain,
    and every other pot reading that joint by −gain · r · δ (tests/stac/test_stac.py)."""
    obs = Observation(data, robot)
    obs.check_observable()
    b_equiv = obs.gauge_equivalent_bias(truth.gain, truth.bias, cal.bias)
    return float(np.nanmax(np.abs((cal.bias - b_equiv) / cal.bias_se)[~obs.fixed_bias]))


def _load() -> str:
    return "load average " + ", ".join(f"{x:.2f}" for x in os.getloadavg())


def full(frames: int, seed: int = 0, jobs: tuple = (1, 2), classical: bool = True) -> None:
    robot, log, opts = _diego(frames, seed)
    truth = Calibration.from_dict(log.truth.params)
    data = log.without_truth()
    print(
        f"\n== thesis size: diego, {log.n_samples} frames, {robot.n_joints} joints, "
        f"{len(robot.sensors.markers)} markers, occlusion {opts.occlusion:.0%}; {_load()}"
    )
    print(
        f"{'method':<16}{'wall s':>8}{'CPU s':>8}{'peak RSS MiB':>14}{'iters':>9}"
        f"{'gain rel err':>14}{'max |z| gain':>14}{'bias':>6}{'q RMSE rad':>12}"
    )
    q_true = log.truth.signals["q"].data
    free_q = _free_joints(robot, data)
    runs = [(f"stac --jobs {j}", StacOptions(max_iterations=30, jobs=j)) for j in jobs]
    if classical:
        runs.append(("classical", StacOptions()))
    for name, options in runs:
        t0, c0 = time.perf_counter(), time.process_time()
        res = calibrate(data, robot, name.split()[0], options)  # method stac or classical, as `stac --method`
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # the process's peak so far
        cal = res.calibration
        gerr = float(np.median(np.abs(cal.gain / truth.gain - 1)))
        zmax = float(np.nanmax(np.abs((cal.gain - truth.gain) / cal.gain_se)))
        zb = _bias_z(robot, data, cal, truth)
        rmse = float(np.sqrt(np.mean((res.q - q_true)[:, free_q] ** 2)))  # gauge joints excluded
        frames_used = [h.frames for h in res.history]
        full_iters = frames_used.count(log.n_samples)
        iters = f"{len(frames_used) - full_iters}+{full_iters}" if name.startswith("stac") else str(cal.fit.iterations)
        print(
            f"{name:<16}{wall:>8.1f}{cpu:>8.1f}{rss:>14.0f}{iters:>9}{gerr:>14.5f}{zmax:>14.2f}{zb:>6.2f}{rmse:>12.4f}"
        )
        if name == "stac --jobs 1":
            stac_res = res
    print(f"({_load()}; STAC iters: on the subset + on all frames;")
    print(" max |z|: |estimate − truth| / SE, biases against the gauge-equivalent truth)")
    _where_the_time_goes(data, robot, stac_res, log.n_samples)


def _where_the_time_goes(data, robot, res, frames: int) -> None:
    """Per-stage wall time from the run above, then a CPU-time profile of a second run."""
    h = res.history
    coarse = [x for x in h if x.frames < frames]
    t_coarse = coarse[-1].seconds if coarse else 0.0
    first = coarse[0].seconds if coarse else h[0].seconds
    print(
        f"\nstages (wall): setup and initial q {first:.1f} s; coarse, {len(coarse)} iterations on "
        f"{coarse[0].frames if coarse else 0} frames: {t_coarse - first:.1f} s; all {frames} frames, "
        f"{len(h) - len(coarse)} iterations: {h[-1].seconds - t_coarse:.1f} s"
    )
    prof = cProfile.Profile(time.process_time)
    prof.enable()
    calibrate(data, robot, options=StacOptions(max_iterations=30))
    prof.disable()
    buf = io.StringIO()
    stats = pstats.Stats(prof, stream=buf).sort_stats("cumulative")
    stats.print_stats(r"(stac/(stac|qphase|pphase|joint_step|model)|robot/batch)\.py", 22)
    print("where STAC's CPU time goes (cProfile, cumulative CPU seconds, second run):")
    print("\n".join(line for line in buf.getvalue().splitlines() if "diegocal/" in line or "cumtime" in line))


def verify(frames: int, seed: int = 0) -> None:
    """Coarse to fine ends at the full-data optimum: the same log with coarse_frames=0."""
    robot, log, _ = _diego(frames, seed)
    data = log.without_truth()
    print(f"\n== coarse to fine vs all frames throughout: diego, {frames} frames; {_load()}")
    out = {}
    for name, cf in (("coarse to fine", StacOptions().coarse_frames), ("all frames", 0)):
        t0 = time.perf_counter()
        out[name] = calibrate(data, robot, options=StacOptions(max_iterations=60, coarse_frames=cf))
        print(f"{name:<16}{time.perf_counter() - t0:>8.1f} s, {len(out[name].history)} iterations")
    a, b = out["all frames"].calibration, out["coarse to fine"].calibration
    for what, x, y, se in (
        ("gain", a.gain, b.gain, a.gain_se),
        ("bias", a.bias, b.bias, a.bias_se),
        ("marker xyz", a.marker_xyz, b.marker_xyz, a.marker_xyz_se),
    ):
        print(f"max |difference| / SE, {what:<11}{np.nanmax(np.abs(x - y) / se):8.3f}")
    dq = np.abs(out["all frames"].q - out["coarse to fine"].q).max()
    print(
        f"max |difference| in q: {dq:.2e} rad; σ: "
        + ", ".join(f"{g} {b.sigma_by_group[g] / v - 1:+.1e}" for g, v in a.sigma_by_group.items())
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=25000)
    ap.add_argument("--verify-frames", type=int, default=5000)
    ap.add_argument("--skip-full", action="store_true")
    ap.add_argument("--skip-schedules", action="store_true")
    ap.add_argument("--skip-verify", action="store_true")
    ap.add_argument("--skip-classical", action="store_true")
    args = ap.parse_args()
    if not args.skip_schedules:
        schedules()
    if not args.skip_full:
        full(args.frames, classical=not args.skip_classical)
    if not args.skip_verify:
        verify(args.verify_frames)


if __name__ == "__main__":
    main()
