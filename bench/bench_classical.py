"""The classical σp = 0 calibration (thesis eq. 2.28-2.29) at thesis size: CPU time and memory.

    .venv/bin/python bench/bench_classical.py [--frames 25000 ...] [--seed 0]

Data as bench/bench_stac.py's full run: robots/diego (38 joints, 30 rotary + 8 linear gimbal
pots, 24 markers) simulated at 100 Hz for frames / 100 s with the simulator's defaults (pot
noise 5 mV, marker noise 2 mm, 10 % occlusion, gains ±20 %, biases ±0.3 rad), seed 0, so that
its rows sit next to STAC's. The gimbal joints are solved from their linear pots
(``nonlinear="constrain"``), as in Table 2.2's σp = 0 row.

Per size: CPU seconds of the fit (time.process_time, the figure to compare on a shared
machine), wall seconds, the process's peak resident memory before and after the fit (MiB; the
simulation's own peak is included, so only an increase is the fit's), residual evaluations,
median relative gain error and joint-angle RMSE against the simulator truth (gauge joints, whose
zero no marker fixes, excluded as in bench_stac), and the load average.
"""

from __future__ import annotations

import argparse
import os
import resource
import time

import numpy as np

from diegocal.robot import load_robot, resolve_robot_dir
from diegocal.sim.kinematics import KinematicsOptions, simulate_kinematics
from diegocal.stac.calibration import Calibration
from diegocal.stac.classical import calibrate_classical
from diegocal.stac.model import Observation
from diegocal.stac.result import StacOptions


def peak_mib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def run(frames: int, seed: int) -> tuple:
    robot = load_robot(resolve_robot_dir("diego", None))
    log = simulate_kinematics(
        robot, KinematicsOptions(duration=frames / 100.0, rate_hz=100.0), np.random.default_rng(seed)
    )
    truth = Calibration.from_dict(log.truth.params)
    data = log.without_truth()
    obs = Observation(data, robot)
    obs.check_observable()
    gauge = {obs.pot_specs[j].joint for j in np.flatnonzero(obs.fixed_bias)}
    free_q = [i for i, n in enumerate(robot.joint_names) if n not in gauge]
    before = peak_mib()
    cpu, wall = time.process_time(), time.perf_counter()
    res = calibrate_classical(data, robot, StacOptions(), nonlinear="constrain")
    cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
    cal = res.calibration
    gerr = float(np.median(np.abs(cal.gain / truth.gain - 1)))
    q_true = log.truth.signals["q"].data
    rmse = float(np.sqrt(np.mean((res.q - q_true)[:, free_q] ** 2)))
    return (log.n_samples, cpu, wall, before, peak_mib(), cal.fit.iterations, cal.fit.converged, gerr, rmse)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, nargs="+", default=[25000])
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    print(f"== classical sigma_p = 0 on diego (nonlinear='constrain'), seed {args.seed}")
    print(
        f"{'frames':>7}{'CPU s':>9}{'wall s':>9}{'RSS before':>12}{'RSS after':>11}{'nfev':>6}{'conv':>6}"
        f"{'gain rel err':>14}{'q RMSE rad':>12}{'load 1m':>9}"
    )
    for frames in args.frames:
        n, cpu, wall, before, after, nfev, conv, gerr, rmse = run(frames, args.seed)
        load = os.getloadavg()[0]
        print(
            f"{n:>7}{cpu:>9.1f}{wall:>9.1f}{before:>12.0f}{after:>11.0f}{nfev:>6}{conv!s:>6}"
            f"{gerr:>14.4f}{rmse:>12.4f}{load:>9.2f}",
            flush=True,
        )


if __name__ == "__main__":
    main()
