"""A mocap clock seconds off the robot's (issue #31): does `diagnose --domain kinematics` name it,
with a value its standard error covers, and say nothing on clean logs?

Two generators: ``project`` (``diegocal simulate kinematics --robot finger --effect
time_offset=S``: smooth multi-sine motion, the simulator draws the sign) and ``offsim`` (the
independent generator of experiments/kinematics_generator.py, on its UR5 or blind iCub:
minimum-jerk moves one joint after another, the shift applied to its 1 kHz path). Per shift
and seed one log, and per seed one clean log, diagnosed with the defaults. A line per log: the
truth, the top finding, the fitted shift ± its standard error and |error| / SE, the other
findings, CPU seconds. The bench reads ``/truth`` to judge; the diagnosis never sees it.

    .venv/bin/python bench/bench_diagnose_far_clock.py [--generator offsim] [--robot ur5]
        [--shifts 0.8,1.5] [--seeds 1,2] [--duration 30]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "experiments"))


def logs(generator: str, robot: str, shifts, seeds, duration: float, folder: Path):
    """(log, robot, shift asked or 0) per shift and seed, then a clean log per seed."""
    from diegocal.robot import load_robot, resolve_robot_dir
    from diegocal.sim.effects import parse_effect

    if generator == "project":
        from diegocal.sim.kinematics import KinematicsOptions, simulate_kinematics

        rob = load_robot(resolve_robot_dir(robot, None))
        for size in (*shifts, 0.0):
            for seed in seeds:
                effects = (parse_effect(f"time_offset={size}"),) if size else ()
                opts = KinematicsOptions(duration=duration, effects=effects)
                yield simulate_kinematics(rob, opts, np.random.default_rng(seed)), rob, size
        return
    import kinematics_generator as gen

    rd = gen.robot_dir(folder, robot)
    rob = load_robot(rd)
    for size in (*shifts, 0.0):
        for seed in seeds:
            session = gen.Session(rd, duration, "time_offset" if size else None, None, size or None, seed, seed)
            yield gen.generate(session), rob, size


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--generator", choices=("project", "offsim"), default="offsim")
    ap.add_argument("--robot", default=None, help="offsim: ur5 or icub (default ur5); project: a bundled robot")
    ap.add_argument("--shifts", default="0.8,1.5", help="shifts to hide, s (comma-separated)")
    ap.add_argument("--seeds", default="1,2")
    ap.add_argument("--duration", type=float, default=30.0)
    args = ap.parse_args(argv)
    from diegocal.diagnose import DiagnoseOptions, diagnose

    robot = args.robot or ("ur5" if args.generator == "offsim" else "finger")
    shifts = [float(x) for x in args.shifts.split(",")]
    seeds = [int(x) for x in args.seeds.split(",")]
    print(f"far clock: {args.generator} {robot}, {args.duration:g}-s logs, load {os.getloadavg()[0]:.1f}")
    named = clean_ok = covered = n_shifted = n_clean = 0
    with tempfile.TemporaryDirectory() as tmp:
        for log, rob, size in logs(args.generator, robot, shifts, seeds, args.duration, Path(tmp)):
            truth = log.truth.effects[0]["values"]["seconds"] if size else None
            start = time.process_time()
            found = diagnose(log, rob, DiagnoseOptions(domain="kinematics")).findings
            cpu = time.process_time() - start
            top = found[0] if found else None
            others = [f"{f.cause}:{f.channel}" for f in found[1:]]
            if truth is None:
                n_clean += 1
                clean_ok += not found
                print(f"  clean: {'nothing' if top is None else f'{top.cause}:{top.channel}'} {others} {cpu:.0f} CPU-s")
                continue
            n_shifted += 1
            line = f"  {truth:+.3f} s: "
            if top is not None and top.cause == "time_offset":
                named += 1
                (p,) = top.term.parameters
                z = abs(p.value - truth) / p.stderr if p.stderr else float("inf")
                covered += z <= 2
                line += f"time_offset {p.value:+.5f} ± {p.stderr:.5f} s, |error|/SE {z:.1f}"
            else:
                line += "nothing" if top is None else f"{top.cause}:{top.channel}"
            print(f"{line}, others {others}, {cpu:.0f} CPU-s")
    print(
        f"named first {named}/{n_shifted}, within 2 SE {covered}/{n_shifted}, clean logs with no finding "
        f"{clean_ok}/{n_clean}; load at the end {os.getloadavg()[0]:.1f}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
