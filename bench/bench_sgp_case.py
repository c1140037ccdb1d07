"""Issue #14's case: the 3-link arm with a hidden cable-like friction on joint 3, 4,000 samples.

    python bench/bench_sgp_case.py [--duration 40] [--no-region] [--no-joint-region]

``diegocal simulate dynamics --robot arm3 --effect position_friction:joint3 --duration 40
--seed 11`` trains; the test logs are ``--seed 12``'s trajectory twice: as the issue ran it (the
simulator also draws another friction: another robot) and of the same robot (seed 11's friction,
:func:`experiments.sgp.common.same_robot`). Fits with ``SGPOptions`` defaults: PR, PRGP, SGP
``--inference auto`` (sparse above 3,000 samples), SGP exact and SGP sparse. Printed per test log:
held-out nMSE per joint (MSE on the measured torque / its variance), each model's difference to PR
and to PRGP with the standard error of the paired per-block difference over 10 contiguous blocks
of the test log, ±2σ coverage, the guard's choice per joint and the fit's CPU seconds (the
machine's load average is printed: compare CPU, not wall).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/ is not installed
from diegocal.evaluate import block_mse, paired_se, score, split_blocks  # noqa: E402
from diegocal.robot import BUNDLED_ROBOTS, load_robot  # noqa: E402
from diegocal.sgp import SGPOptions, fit_dynamics  # noqa: E402
from diegocal.sgp.model import DEFAULT_GUARD  # noqa: E402
from diegocal.sim.dynamics import DynamicsOptions, simulate_dynamics  # noqa: E402
from diegocal.sim.effects import parse_effects  # noqa: E402
from experiments.sgp.common import same_robot  # noqa: E402

FITS = {
    "PR": SGPOptions(kind="pr"),
    "PRGP": SGPOptions(kind="prgp"),
    "SGP auto": SGPOptions(kind="sgp"),
    "SGP exact": SGPOptions(kind="sgp", inference="exact"),
    "SGP sparse": SGPOptions(kind="sgp", inference="sparse"),
}


def simulate(robot, seed: int, friction=None, duration: float = 40.0):
    opts = DynamicsOptions(duration=duration, effects=parse_effects(["position_friction:joint3"]), **(friction or {}))
    return simulate_dynamics(robot, opts, np.random.default_rng(seed))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=40.0, help="training run, s (100 Hz)")
    parser.add_argument("--no-region", action="store_true", help="add 'SGP no region': SGP with sgp-fit --no-region")
    parser.add_argument(
        "--no-joint-region",
        action="store_true",
        help="add 'SGP no joint cut': SGP with sgp-fit --no-joint-region",
    )
    args = parser.parse_args()
    fits = dict(FITS)
    if args.no_region:
        fits["SGP no region"] = SGPOptions(
            kind="sgp", guard_options=replace(DEFAULT_GUARD, region=False, joint_region=False)
        )
    if args.no_joint_region:
        fits["SGP no joint cut"] = SGPOptions(kind="sgp", guard_options=replace(DEFAULT_GUARD, joint_region=False))
    sys.stdout.reconfigure(line_buffering=True)
    head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    print(f"diegocal commit {head or 'unknown'}; load average {os.getloadavg()[0]:.1f}")
    robot = load_robot(BUNDLED_ROBOTS / "arm3")
    train = simulate(robot, 11, duration=args.duration)
    tests = {"seed 12": simulate(robot, 12), "same robot": simulate(robot, 12, same_robot(train, robot))}
    models, cpu = {}, {}
    for label, options in fits.items():
        start = time.process_time()
        models[label] = fit_dynamics(train, robot, options)
        cpu[label] = time.process_time() - start
    for name, log in tests.items():
        measured = log.stream("tau").data
        labels = split_blocks(log.n_samples, 10).labels()
        blocks, cover = {}, {}
        for label, model in models.items():
            pred = model.predict(log)
            blocks[label] = block_mse((pred.tau - measured) ** 2 / measured.var(axis=0), labels)
            cover[label] = score(measured, pred.tau, model.joint_names, std=pred.tau_std).coverage
        print(f"\n== test {name}: held-out nMSE per joint; difference to PR and to PRGP ± one SE (10 blocks)")
        for label, b in blocks.items():
            cells = []
            for ref in ("PR", "PRGP"):
                d, se = paired_se(b, blocks[ref])
                cells.append(" ".join(f"{x:+.5f}±{s:.5f}" for x, s in zip(d, se, strict=True)))
            g = models[label].hyperparameters_
            choice = [g[j].get("guard_choice", "-") for j in models[label].joint_names]
            print(
                f"{label:<11}" + "".join(f"{v:>9.5f}" for v in b.mean(0)) + f"  vs PR {cells[0]}  vs PRGP {cells[1]}"
                f"  ±2σ {' '.join(f'{c:.2f}' for c in cover[label])}  {'/'.join(choice)}  {cpu[label]:.1f} CPU-s"
            )
    print(f"\nload average at the end {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
