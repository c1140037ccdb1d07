"""What ±2σ coverage a calibrated band gives on one held-out run: PR's per-run coverage beside an
oracle band's, over many training runs, with and without the hidden friction (issue #14).

    python bench/bench_sgp_coverage.py [--size 200] [--runs 200]

Data: the sizes bench's case (:func:`experiments.sgp.common.friction_case`): arm3 at 50 Hz, for
each run s an N-sample training run of seed s and 2,000 samples of seed 1000 + s's trajectory of
the same robot; "without" is the same runs with the hidden friction off (``hidden=False``), where
PR is the true model and its posterior the exact Bayesian one.

The oracle band knows the true spread of W's error: ``Σ = mean over the other runs of δ δᵀ``,
δ = ŵ − w, with w the run's true base parameters (least squares on a noise-free, effect-free
log of its robot: ``/truth`` read here for the analysis only, as the experiments read it to
score); its band is ``f Σ fᵀ + σ²`` with the simulator's σ. It is calibrated over runs by
construction, yet per run it covers whatever the one draw of δ gives: the test's 2,000 samples
share it. PR's is its own (eq. 3.20 or W's robust variance, the larger). Printed per joint: the
mean coverage over runs and how many runs fall below 0.85 / above 0.99. With the friction, the
oracle's joint 3 lacks the effect itself (not a W error): read joints 1-2 there. 200 runs of 200
samples take about 20 s.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/ is not installed
sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_sgp_sizes import N_TEST  # noqa: E402

from diegocal.evaluate import COVERAGE_BAND  # noqa: E402
from diegocal.parallel import one_blas_thread  # noqa: E402
from diegocal.robot import BUNDLED_ROBOTS, load_robot  # noqa: E402
from diegocal.sgp import SGPOptions, fit_dynamics  # noqa: E402
from diegocal.sgp.model import log_arrays  # noqa: E402
from diegocal.sim.dynamics import DynamicsOptions, simulate_dynamics  # noqa: E402
from experiments.sgp.common import CASE_NOISE, SCALE_RATE, friction_case, same_robot  # noqa: E402


def one_run(robot, N: int, seed: int, hidden: bool) -> dict:
    """PR on run ``seed``: its W error δ (m,), test features (T, n, m), measured test torque and
    PR's mean and std (T, n)."""
    train = friction_case(robot, N, seed, hidden=hidden).slice(0, N)
    robot_of_run = same_robot(train, robot)
    test = friction_case(robot, N_TEST, 1000 + seed, robot_of_run, hidden=hidden).slice(0, N_TEST)
    model = fit_dynamics(train, robot, SGPOptions(kind="pr"))
    clean_opts = DynamicsOptions(duration=N_TEST / SCALE_RATE + 0.1, rate_hz=SCALE_RATE, noise=0.0, **robot_of_run)
    q, qd, qdd, tau = log_arrays(simulate_dynamics(robot, clean_opts, np.random.default_rng(5000 + seed)), robot)
    F = model.features(q, qd, qdd)
    w_true = np.linalg.lstsq(F.reshape(-1, F.shape[2]), tau.reshape(-1), rcond=None)[0]
    q, qd, qdd, tau = log_arrays(test, robot)
    pred = model.predict_arrays(q, qd, qdd)
    out = {"delta": model.gp_.w_ - w_true, "F": model.features(q, qd, qdd), "tau": tau}
    return out | {"mean": pred.tau, "std": pred.tau_std}


def coverages(runs: list) -> tuple[np.ndarray, np.ndarray]:
    """(runs, n) coverage of PR's band and of the oracle band (leave-one-out Σ)."""
    D = np.array([r["delta"] for r in runs])
    own, oracle = [], []
    for i, r in enumerate(runs):
        rest = np.delete(D, i, axis=0)
        var = np.einsum("tjm,mk,tjk->tj", r["F"], rest.T @ rest / len(rest), r["F"]) + CASE_NOISE**2
        err = np.abs(r["mean"] - r["tau"])
        own.append(np.mean(err <= 2 * r["std"], axis=0))
        oracle.append(np.mean(err <= 2 * np.sqrt(var), axis=0))
    return np.array(own), np.array(oracle)


def row(label: str, cov: np.ndarray) -> str:
    lo, hi = COVERAGE_BAND
    cells = [f"{c.mean():.3f} {np.sum(c < lo):3d}/{np.sum(c > hi):<3d}" for c in cov.T]
    return f"{label:28s} " + "   ".join(cells)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=200, help="training samples per run")
    ap.add_argument("--runs", type=int, default=200, help="training runs (seeds 1..runs)")
    args = ap.parse_args(argv)
    if args.runs < 3 or args.size < 20:
        sys.exit(f"bench_sgp_coverage: need --runs ≥ 3 and --size ≥ 20, got {args.runs}, {args.size}")
    sys.stdout.reconfigure(line_buffering=True)
    robot = load_robot(BUNDLED_ROBOTS / "arm3")
    print(f"python bench/bench_sgp_coverage.py {' '.join(argv or sys.argv[1:])}; load {os.getloadavg()[0]:.2f}")
    print(f"arm3, {args.runs} training runs of {args.size} samples, each tested on {N_TEST} samples of another run")
    print(f"per joint: mean ±2σ coverage over runs, runs below {COVERAGE_BAND[0]} / above {COVERAGE_BAND[1]}\n")
    with one_blas_thread():
        for hidden in (False, True):
            runs = [one_run(robot, args.size, s, hidden) for s in range(1, args.runs + 1)]
            own, oracle = coverages(runs)
            what = "with the hidden friction" if hidden else "PR the true model"
            print(f"{what}:\n{row('  PR (its own band)', own)}\n{row('  oracle (true spread of W)', oracle)}")
    print(f"\nload average at the end {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
