"""The thesis's SGP experiments (ch. 3) on simulated robots, full versions: tables of held-out nMSE
per method, the SGP guard across seeds, and held-out ±2σ coverage per method and cell.

    .venv/bin/python bench/bench_sgp_experiments.py [--seeds 5] [--only pendulum,wheel,arm3]
                                                    [--quick] [--arm-rate HZ]

Methods: PR (parametric, eq. 3.25), GP (eq. 3.21), PRGP (two-stage, §3.4.1), SGP (joint, with the
guard of diegocal.sgp), SGP-noguard (plain ML-II SGP). nMSE is against the noise-free simulated
target (torque; for the reaction wheel's forward model, the predictable acceleration), normalised
by its variance over the test log; coverage is the fraction of measured targets within ±2σ of the
prediction. The test logs are of the training run's robot (its friction). Each nMSE cell is the seed
mean ± its standard error; the last column is SGP's verdict against the best of PR, GP and PRGP
(experiments.sgp.common.Verdict: "tied" = behind by at most one paired standard error
over the seeds). The fit times are the reference for the methods' cost, measured in the same run.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/ is not installed
from experiments.sgp import (  # noqa: E402
    ArmConfig,
    PendulumConfig,
    WheelConfig,
    aggregate,
    run_arm3,
    run_pendulum,
    run_reaction_wheel,
    table,
)
from experiments.sgp.common import spread_table, verdicts  # noqa: E402

#: Experiment -> (runner, full config, quick config, data-poor (test, region) cells).
EXPERIMENTS = {
    "pendulum": (
        run_pendulum,
        PendulumConfig(),
        PendulumConfig(train_s=6.0, test_s=4.0),
        [("whirl", "sparse [-2,0]")],
    ),
    "wheel": (
        run_reaction_wheel,
        WheelConfig(),
        WheelConfig(train_s=8.0, test_s=5.0),
        [("pole-up", "all")],
    ),
    "arm3": (run_arm3, ArmConfig(), ArmConfig(train_s=6.0, test_s=3.0), [("vertical", "all")]),
}


def guard_table(scores, poor) -> str:
    """Guard on (SGP) vs off (SGP-noguard) in the data-poor cells: mean and worst seed."""
    mean = aggregate(scores, "nmse", np.mean)
    worst = aggregate(scores, "nmse", np.max)
    cols = "".join(f"{c:>10}" for c in ("mean on", "mean off", "worst on", "worst off"))
    head = f"{'test':<10}{'region':<16}{'joint':<8}" + cols
    lines = [head, "-" * len(head)]
    for key in sorted({k[1:] for k in mean if (k[1], k[2]) in poor}):
        on, off = ("SGP",) + key, ("SGP-noguard",) + key
        if on in mean and off in mean:
            lines.append(
                f"{key[0]:<10}{key[1]:<16}{key[2]:<8}{mean[on]:>10.4g}{mean[off]:>10.4g}"
                f"{worst[on]:>10.4g}{worst[off]:>10.4g}"
            )
    return "\n".join(lines)


def fit_times(scores) -> str:
    per = {}
    for s in scores:
        per.setdefault(s.method, {})[(s.seed,)] = s.fit_s
    return "  ".join(f"{m} {np.mean(list(v.values())):.1f}s" for m, v in per.items())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--only", default="pendulum,wheel,arm3")
    ap.add_argument("--quick", action="store_true", help="reduced sizes (the tests' scale)")
    ap.add_argument("--arm-rate", type=float, default=None, help="arm3 sample rate, Hz (default 20: 200 samples)")
    args = ap.parse_args()
    unknown = sorted(set(args.only.split(",")) - set(EXPERIMENTS))
    if unknown:
        sys.exit(f"bench_sgp_experiments: unknown experiment(s) {', '.join(unknown)}; known: {', '.join(EXPERIMENTS)}")
    sys.stdout.reconfigure(line_buffering=True)  # the library runs BLAS on one thread itself
    head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    print(
        f"diegocal commit {head or 'unknown'}; command: python bench/bench_sgp_experiments.py {' '.join(sys.argv[1:])}"
    )
    seeds = tuple(range(args.seeds))
    for name in args.only.split(","):
        run, full, quick, poor = EXPERIMENTS[name]
        if name == "arm3" and args.arm_rate:
            full, quick = (replace(c, rate_hz=args.arm_rate) for c in (full, quick))
        start = time.perf_counter()
        scores = run(seeds=seeds, cfg=quick if args.quick else full)
        wall = time.perf_counter() - start
        print(f"\n=== {name}: {len(seeds)} seeds, {wall:.0f} s; mean fit time per method: {fit_times(scores)}")
        print(spread_table(scores, title=f"{name}: held-out nMSE, seed mean ± standard error (* lowest)"))
        labels = [v.label for v in verdicts(scores)]
        print(
            f"SGP: {labels.count('best')} best, {labels.count('tied')} tied, {labels.count('worse')} worse "
            f"of {len(labels)} cells"
        )
        print()
        print(table(scores, "nmse", np.max, title=f"{name}: held-out nMSE, worst seed"))
        print()
        print(f"{name}: SGP guard, nMSE in the data-poor cells over {len(seeds)} seeds")
        print(guard_table(scores, poor))
        print()
        print(
            table(
                scores,
                "coverage",
                np.mean,
                title=f"{name}: held-out coverage of ±2σ, seed mean (* closest to 0.95; data-poor cells: "
                f"{', '.join(f'{t} {r}' for t, r in poor)})",
            )
        )


if __name__ == "__main__":
    main()
