"""SGP against PR and PRGP at every size, over independent training runs: issue #14's "at every
size from 200 to 20,000 samples, beyond noise" judged across seeds, not on one trajectory.

    python bench/bench_sgp_sizes.py [--sizes 200,500,1000,2000,5000,10000,20000] [--seeds 1-5]
                                    [--workers 2]

Data: the scale bench's robot and effect (bundled 3-link arm, hidden cable-like friction on joint
3 above 1.78 rad, 50 Hz, 0.01 N·m noise; :func:`bench_sgp_scale.simulate`). For each size N and
seed s: training = an N-sample excitation run of seed s; test = 2,000 samples of seed 1000 + s's
trajectory of the *same* robot (seed s's friction). PR, PRGP and SGP with the defaults a user gets
(``SGPOptions(kind=...)``, inference auto). Printed per (N, s): held-out nMSE per joint, ±2σ
coverage, the SGP guard's choice and how many training samples lie above the onset (the effect's
support: a run may visit it once or not at all).

Coverage per run: the band's width is set by W's error, one draw per training run shared by all
2,000 test samples, so a calibrated band covers 0.95 on average over runs, not on every run. Per N
the summary counts the runs whose coverage falls below 0.85 / above 0.99 per joint, beside the same
count for a band known to be calibrated: PR on each seed's run without the hidden friction (same
trajectories and noise), where PR is the true model (its held-out coverage averages 0.95 over
redraws of one run's noise: ``tests/sgp/test_band_calibration.py``).

Why seeds: the scale bench cuts one 20,000-sample run, so its 2,000-sample cell is one draw of
where the arm went; that draw held 39 samples above the onset in one stretch, no cross-validation
fold could see the effect, and the SGP fell back to PR where PRGP's GP happened to carry it. The
question "is the SGP worse at this size?" is about the estimator, so the verdict pairs the models
on each seed's test and averages over seeds: the SGP minus a reference, mean ± one standard error
over the seeds; "better"/"worse" beyond one SE and 0.1 % of the reference's nMSE, else "tied".
Per seed the same rule on 10 contiguous blocks of the test gives the counts "w/t/l" (SGP
better / tied / worse on that seed).

The fits run in ``--workers`` processes (one BLAS thread each); times are not compared here (the
scale bench does that), so the load does not matter.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/ is not installed
sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_sgp_scale import N_TEST, arrays, simulate, verdict  # noqa: E402

from diegocal.evaluate import COVERAGE_BAND, block_mse, paired_se, split_blocks  # noqa: E402
from diegocal.parallel import one_blas_thread  # noqa: E402
from diegocal.robot import BUNDLED_ROBOTS, load_robot  # noqa: E402
from diegocal.sgp import SGPOptions, fit_dynamics  # noqa: E402
from diegocal.sim.dynamics import default_region  # noqa: E402
from experiments.sgp.common import same_robot  # noqa: E402

SIZES = (200, 500, 1000, 2000, 5000, 10000, 20000)
SEEDS = (1, 2, 3, 4, 5)
KINDS = ("pr", "prgp", "sgp")
BLOCKS = 10  # contiguous blocks of the test log
EXACT = "pr, no friction"  # the reference: PR where it is the true model


def run_cell(cell: tuple) -> dict:
    """One (N, seed): per kind the test's per-block nMSE (BLOCKS, n) and ±2σ coverage (n,)."""
    N, seed = cell
    with one_blas_thread():
        robot = load_robot(BUNDLED_ROBOTS / "arm3")
        train = simulate(robot, N, seed=seed).slice(0, N)
        test = simulate(robot, N_TEST, seed=1000 + seed, friction=same_robot(train, robot))
        q, qd, qdd, tau = arrays(test, robot, N_TEST)
        labels = split_blocks(N_TEST, BLOCKS).labels()
        onset = default_region(robot, 2)[0]  # where the simulator's friction on joint 3 starts
        out = {"above": int(np.sum(arrays(train, robot)[0][:, 2] >= onset))}
        for kind in KINDS:
            model = fit_dynamics(train, robot, SGPOptions(kind=kind))
            pred = model.predict_arrays(q, qd, qdd)
            out[kind] = block_mse((pred.tau - tau) ** 2 / tau.var(axis=0), labels)
            out[kind + " coverage"] = coverage(pred, tau)
            if kind == "sgp":
                out["choice"] = [model.hyperparameters_[j].get("guard_choice", "-") for j in model.joint_names]
        out[EXACT + " coverage"] = true_model_coverage(robot, N, seed)
        return out


def true_model_coverage(robot, N: int, seed: int) -> np.ndarray:
    """(n,) ±2σ held-out coverage of PR on seed's run *without* the hidden friction (same
    trajectories, robot and noise): PR is then the true model and its band eq. (3.20)'s Bayesian
    posterior, so how far single runs stray from 0.95 is what a calibrated band gives at N."""
    train = simulate(robot, N, seed=seed, hidden=False).slice(0, N)
    test = simulate(robot, N_TEST, seed=1000 + seed, friction=same_robot(train, robot), hidden=False)
    q, qd, qdd, tau = arrays(test, robot, N_TEST)
    return coverage(fit_dynamics(train, robot, SGPOptions(kind="pr")).predict_arrays(q, qd, qdd), tau)


def coverage(pred, tau: np.ndarray) -> np.ndarray:
    """(n,) fraction of the measured torques ``tau`` (T, n) within ±2σ of ``pred``."""
    return np.mean(np.abs(pred.tau - tau) <= 2.0 * pred.tau_std, axis=0)


def outside(cov: np.ndarray) -> str:
    """Runs (rows of ``cov`` (seeds, n)) below / above COVERAGE_BAND, per joint."""
    lo, hi = COVERAGE_BAND
    return ",".join(f"{np.sum(c < lo)}/{np.sum(c > hi)}" for c in cov.T)


def parse_seeds(text: str) -> tuple:
    if "-" in text:
        lo, hi = (int(s) for s in text.split("-"))
        return tuple(range(lo, hi + 1))
    return tuple(int(s) for s in text.split(","))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default=",".join(map(str, SIZES)), help="comma list of training sizes")
    ap.add_argument("--seeds", default=f"{SEEDS[0]}-{SEEDS[-1]}", help="a range 1-5 or a comma list")
    ap.add_argument("--workers", type=int, default=2, help="processes, one fit each")
    args = ap.parse_args(argv)
    try:
        sizes, seeds = tuple(int(s) for s in args.sizes.split(",")), parse_seeds(args.seeds)
    except ValueError:
        sys.exit(f"bench_sgp_sizes: --sizes and --seeds expect integers, got {args.sizes!r}, {args.seeds!r}")
    if len(seeds) < 2 or args.workers < 1:
        sys.exit("bench_sgp_sizes: need at least 2 seeds (a standard error over seeds) and 1 worker")
    sys.stdout.reconfigure(line_buffering=True)
    head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    print(f"diegocal commit {head or 'unknown'}; python bench/bench_sgp_sizes.py {' '.join(argv or sys.argv[1:])}")
    onset = default_region(load_robot(BUNDLED_ROBOTS / "arm3"), 2)[0]
    what = f"arm3, hidden friction on joint3 above {onset:.2f} rad; {len(seeds)} seeds"
    print(f"{what}; load average {os.getloadavg()[0]:.2f}\n")
    cells = sorted(((N, s) for N in sizes for s in seeds), key=lambda c: -c[0])  # the long fits first
    results = {}
    with ProcessPoolExecutor(args.workers) as pool:
        futures = {pool.submit(run_cell, cell): cell for cell in cells}
        for future in as_completed(futures):
            N, seed = futures[future]
            results[(N, seed)] = future.result()
            print(f"  fitted N={N} seed {seed} ({len(results)}/{len(cells)})", file=sys.stderr)
    print(f"{'N':>6} {'seed':>4} {'above':>5}  held-out nMSE per joint (pr | prgp | sgp), ±2σ coverage, SGP choice")
    for N in sizes:
        for s in seeds:
            r = results[(N, s)]
            err = " | ".join(" ".join(f"{v:.2e}" for v in r[k].mean(0)) for k in KINDS)
            cov = " | ".join(" ".join(f"{v:.2f}" for v in r[k + " coverage"]) for k in KINDS)
            print(f"{N:6d} {s:4d} {r['above']:5d}  {err}   cov {cov}   {'/'.join(r['choice'])}")
    n = len(results[cells[0]]["sgp"][0])
    print(
        f"\nSGP minus PR and minus PRGP per joint: mean over {len(seeds)} seeds ± one SE over seeds "
        f"[seeds better/tied/worse on {BLOCKS} test blocks]; coverage mean (min) over seeds"
    )
    for N in sizes:
        rows = [results[(N, s)] for s in seeds]
        mean = {k: np.array([r[k].mean(0) for r in rows]) for k in KINDS}  # (seeds, n)
        words = []
        for ref in ("pr", "prgp"):
            for j in range(n):
                d = mean["sgp"][:, j] - mean[ref][:, j]
                se = d.std(ddof=1) / np.sqrt(len(d))
                per_seed = [verdict(*(x[j] for x in paired_se(r["sgp"], r[ref])), r[ref][:, j].mean()) for r in rows]
                counts = "/".join(str(per_seed.count(w)) for w in ("better", "tied", "worse"))
                word = verdict(d.mean(), se, mean[ref][:, j].mean())
                words.append(f"vs {ref} j{j + 1} {word} ({d.mean():+.2g} ± {se:.2g}) [{counts}]")
        cover = " ".join(
            f"{k} " + ",".join(f"{c.mean():.2f}({c.min():.2f})" for c in np.array([r[k + " coverage"] for r in rows]).T)
            for k in KINDS
        )
        runs = " ".join(f"{k} " + outside(np.array([r[k + " coverage"] for r in rows])) for k in (*KINDS, EXACT))
        print(f"{N:6d}  " + "; ".join(words) + f"\n        coverage {cover}\n        runs below/above {runs}")
    print(f"\nload average at the end {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
