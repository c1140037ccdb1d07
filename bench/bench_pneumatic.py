"""Bench: the 9-parameter pneumatic fit on all 76 diego chambers at 10^5 samples each.

Prints (1) simulation cost, (2) fit wall time and peak memory with the analytic Jacobian and,
in the same run, with scipy's finite-difference Jacobian (the reference), (3) the 2-s drift
distribution on a held-out session (thesis Fig. 4.13: < 10 % of Pc - Pr for every chamber,
usually < 4 %), (4) multi-start spread on a few chambers (§4.5.3).

    .venv/bin/python bench/bench_pneumatic.py [--jobs 2] [--sessions 10] [--log cache.h5]
"""

from __future__ import annotations

import argparse
import resource
import sys
import time
import tracemalloc
from pathlib import Path

import numpy as np

from diegocal.io import load_log, save_log
from diegocal.pneumatic import FitOptions, chamber_data, drift, fit_chamber, fit_chambers
from diegocal.pneumatic.params import NAMES
from diegocal.robot import load_robot
from diegocal.sim.pneumatics import PneumaticSimOptions, simulate_pneumatics

ROBOT = Path(__file__).resolve().parents[1] / "robots" / "diego"


def peak_rss_mb() -> tuple[float, float]:
    """Peak resident memory (MB) of this process and of its largest child so far."""
    k = 1024.0 if sys.platform != "darwin" else 1024.0**2
    return (
        resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / k,
        resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / k,
    )


def cpu_seconds() -> float:
    """User + system CPU time of this process and its finished children, s."""
    me, kids = (
        resource.getrusage(resource.RUSAGE_SELF),
        resource.getrusage(resource.RUSAGE_CHILDREN),
    )
    return me.ru_utime + me.ru_stime + kids.ru_utime + kids.ru_stime


def traced_peak_mb(data) -> float:
    """Peak memory allocated (tracemalloc, numpy included) by one chamber's fit, MB."""
    tracemalloc.start()
    fit_chamber(data, FitOptions())
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return peak / 2**20


def simulate(robot, sessions: int, seed: int, cache: Path | None):
    if cache is not None and cache.exists():
        return load_log(cache), 0.0
    t = time.perf_counter()
    log = simulate_pneumatics(
        robot, PneumaticSimOptions(duration=100.0, sessions=sessions, seed=seed)
    )
    wall = time.perf_counter() - t
    if cache is not None:
        save_log(log, cache)
    return log, wall


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--sessions", type=int, default=10, help="100-s sessions (10 -> 10^5 samples)")
    ap.add_argument("--log", type=Path, default=None, help="cache the training log here")
    ap.add_argument("--skip-fd", action="store_true", help="skip the finite-difference reference")
    args = ap.parse_args()
    robot = load_robot(ROBOT)
    names = robot.sensors.chamber_names

    log, sim_wall = simulate(robot, args.sessions, 1, args.log)
    held, held_wall = simulate(robot, 1, 2, None)
    print(f"== simulation (thin-plate physics, {len(names)} chambers, 20 sub-steps/tick)")
    print(
        f"training log: {log.n_samples} samples per chamber, {sim_wall:.1f} s wall"
        + (" (cached)" if sim_wall == 0 else "")
    )
    print(f"held-out log: {held.n_samples} samples per chamber, {held_wall:.1f} s wall")

    datasets = [chamber_data(log, robot.sensors, n) for n in names]
    rows = []
    fits = None
    for label, jac in (
        ("analytic Jacobian", "analytic"),
        ("finite differences (reference)", "2-point"),
    ):
        if jac == "2-point" and args.skip_fd:
            continue
        t, cpu = time.perf_counter(), cpu_seconds()
        batch = fit_chambers(datasets, FitOptions(jacobian=jac), jobs=args.jobs)
        wall, cpu = time.perf_counter() - t, cpu_seconds() - cpu
        nfev = np.median([f.nfev for f in batch.fits.values()])
        rows.append(
            (
                label,
                wall,
                cpu,
                len(batch.fits),
                nfev,
                *peak_rss_mb(),
                np.median([f.cost for f in batch.fits.values()]),
            )
        )
        if fits is None:
            fits = batch.fits
    print(f"\n== fit: {len(names)} chambers x {log.n_samples} samples, --jobs {args.jobs}")
    print(
        f"{'method':<32}{'wall s':>8}{'CPU s':>8}{'fitted':>8}{'nfev':>6}{'RSS main MB':>13}"
        f"{'RSS worker MB':>15}{'median cost':>13}"
    )
    for r in rows:
        print(
            f"{r[0]:<32}{r[1]:8.1f}{r[2]:8.1f}{r[3]:8d}{r[4]:6.0f}{r[5]:13.0f}{r[6]:15.0f}"
            f"{r[7]:13.4g}"
        )
    if len(rows) == 2:
        print(f"analytic Jacobian: {rows[1][2] / rows[0][2]:.1f}x less CPU than finite differences")
    print(
        f"CPU per chamber (analytic): {rows[0][2] / len(names):.2f} s; an idle 2-core machine "
        f"needs about {rows[0][2] / 2:.0f} s wall for all {len(names)} (wall above: shared machine)"
    )
    print(f"peak memory of one chamber's fit (tracemalloc): {traced_peak_mb(datasets[0]):.0f} MB")
    print(
        "(RSS includes the training log held by the main process and inherited by forked workers)"
    )

    d_fit = np.array([fits[n].drift_2s for n in names])
    d_held = np.array(
        [drift(fits[n].params, chamber_data(held, robot.sensors, n)).final for n in names]
    )
    print("\n== 2-s open-loop drift, RMS error / (Pc - Pr), 48 starts per chamber (Fig. 4.13)")
    print(f"{'data':<22}{'median':>8}{'p90':>8}{'max':>8}{'< 4 %':>8}{'< 10 %':>8}")
    for label, d in (("fit log", d_fit), ("held-out session", d_held)):
        print(
            f"{label:<22}{np.median(d):8.1%}{np.percentile(d, 90):8.1%}{d.max():8.1%}"
            f"{(d < 0.04).sum():>5d}/{d.size}{(d < 0.10).sum():>5d}/{d.size}"
        )
    worst = np.argsort(d_held)[::-1][:5]
    print("worst held-out: " + ", ".join(f"{names[i]} {d_held[i]:.1%}" for i in worst))

    print("\n== multi-start (5 starts, seeded) on 6 chambers, first 2 sessions (§4.5.3)")
    sub = log.slice(0, min(log.n_samples, 20002))
    picks = names[:: max(1, len(names) // 6)][:6]
    batch = fit_chambers(
        [chamber_data(sub, robot.sensors, n) for n in picks],
        FitOptions(starts=5, seed=7),
        jobs=args.jobs,
    )
    print(f"{'chamber':<22}{'cost spread (rel)':>18}{'max |Δc|/SE':>14}")
    for n, f in batch.fits.items():
        costs = np.array(f.start_costs)
        se = np.array([f.params.stderr[k] for k in NAMES])
        print(
            f"{n:<22}{np.ptp(costs) / costs.min():18.2e}"
            f"{np.max(np.ptp(f.start_params, axis=0) / se):14.3g}"
        )


if __name__ == "__main__":
    main()
