"""How many blocks? `diagnose --domain dynamics` on logs whose torque noise is correlated, as real logs' is.

    python bench/bench_diagnose_blocks.py                    # 15.6 s, 5 Hz noise, 10 and 20 blocks
    python bench/bench_diagnose_blocks.py --logs 40 --duration 30 --cutoff 0 --seed 7

The real logs are low-pass filtered before they are diagnosed: the TX40's torques at 10 Hz
(zero-phase, order 4) at 200 Hz, TIAGo's at 5 Hz at 100 Hz (``sample_data/real/README.md``), so
their noise is correlated over several samples, where the simulator's is i.i.d. This bench
simulates arm3 logs (the dynamics bench's robot) whose torque noise is i.i.d. Gaussian filtered
the same way (``scipy.signal.sosfiltfilt``, Butterworth order 4, ``--cutoff`` Hz at 100 Hz;
0 = i.i.d.), rescaled to the simulator's RMS (0.01 N·m) per joint, and diagnoses each log with
each ``--blocks`` value: ``--logs`` clean logs (a *false alarm* is any finding) and ``--logs``
logs hiding one cause of ``bench_diagnose.py``'s dynamics list in turn (3-10 × the noise on a
random joint, the same sizes and baselines as there; *named* = the top finding has its cause and
joint and a positive held-out gain). Defaults: 15.6 s, the TX40's 1,563 samples at 100 Hz, with
its cut-off relative to the sampling rate (0.05).

Seeds are fresh on every run (printed; ``--seed`` repeats a run). The bench reads ``/truth`` to
judge; the diagnosis never sees it.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent))

from bench_diagnose import BASELINE_FOR, CASES, ROBOT_FOR, TORQUE_NOISE, _sized_torque_effect  # noqa: E402

RATE_HZ = 100.0


def filtered_noise(shape, cutoff: float, rng) -> np.ndarray:
    """(T, n) noise of RMS TORQUE_NOISE per column: i.i.d. Gaussian, low-pass filtered at ``cutoff``
    Hz (zero-phase Butterworth of order 4, as the real logs' import) when ``cutoff`` > 0."""
    from scipy.signal import butter, sosfiltfilt

    e = rng.normal(size=shape)
    if cutoff > 0:
        e = sosfiltfilt(butter(4, cutoff, fs=RATE_HZ, output="sos"), e, axis=0)
    return e * (TORQUE_NOISE / e.std(axis=0))


def simulate(cause: str | None, seed: int, duration: float, cutoff: float):
    """An arm3 log hiding ``cause`` (None: clean) with correlated torque noise, and its robot."""
    from diegocal.io import make_stream
    from diegocal.robot import load_robot, resolve_robot_dir
    from diegocal.sim.dynamics import DynamicsOptions, simulate_dynamics
    from diegocal.sim.effects import check_effects

    robot = load_robot(resolve_robot_dir(CASES["dynamics"]["robot"], None))
    opts = DynamicsOptions(duration=duration, rate_hz=RATE_HZ, noise=0.0, **ROBOT_FOR.get(cause, {}))
    if cause and cause != "payload":
        request, regions = _sized_torque_effect(robot, cause, seed, opts)
        opts = replace(opts, effects=check_effects([request], "dynamics"), regions=regions)
    elif cause:
        opts = replace(opts, effects=check_effects([cause], "dynamics"))
    log = simulate_dynamics(robot, opts, np.random.default_rng(seed))
    tau = log.stream("tau")
    noisy = tau.data + filtered_noise(tau.data.shape, cutoff, np.random.default_rng([seed, 3]))
    return log.with_streams(tau=make_stream(tau.names, noisy)), robot


def run_one(cause, seed, duration, cutoff, blocks) -> list[tuple]:
    """One log diagnosed with each number of blocks: (blocks, named or alarm, seconds) each."""
    from diegocal.diagnose import DiagnoseOptions, diagnose

    log, robot = simulate(cause, seed, duration, cutoff)
    channel = log.truth.effects[0]["channel"] if cause else None
    out = []
    for n in blocks:
        options = replace(DiagnoseOptions(domain="dynamics", n_blocks=n), **BASELINE_FOR.get(cause, {}))
        start = time.perf_counter()
        findings = diagnose(log, robot, options).findings
        seconds = time.perf_counter() - start
        if cause is None:
            hit = bool(findings)
        else:
            top = findings[0] if findings else None
            hit = (
                top is not None
                and (top.cause, top.channel) == (cause, channel)
                and float(top.gain().get("reduction", float("nan"))) > 0
            )
        out.append((n, hit, seconds))
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--logs", type=int, default=30, help="Clean logs (and as many hiding a cause).")
    parser.add_argument("--duration", type=float, default=15.6, help="Log length, s (100 Hz).")
    parser.add_argument("--cutoff", type=float, default=5.0, help="Noise low-pass cut-off, Hz; 0 = i.i.d.")
    parser.add_argument("--blocks", default="10,20", help="Numbers of blocks to compare, comma separated.")
    parser.add_argument("--seed", type=int, default=None, help="Repeat a run (default: fresh seeds, printed).")
    args = parser.parse_args(argv)
    blocks = [int(b) for b in args.blocks.split(",") if b.strip()]
    if args.logs < 1 or not blocks or min(blocks) < 5:
        print("error: --logs must be at least 1 and every --blocks at least 5", file=sys.stderr)
        return 2
    seed = args.seed if args.seed is not None else int(np.random.SeedSequence().entropy % 2**31)
    print(
        f"bench_diagnose_blocks: seed {seed}, {args.logs} + {args.logs} arm3 logs of {args.duration} s, "
        f"noise low-passed at {args.cutoff} Hz (0 = i.i.d.), load {os.getloadavg()[0]:.1f}"
    )
    from threadpoolctl import threadpool_limits

    threadpool_limits(1)
    causes = CASES["dynamics"]["causes"]
    seeds = np.random.SeedSequence(seed).generate_state(2 * args.logs)
    jobs = [(causes[i % len(causes)], int(seeds[i])) for i in range(args.logs)]
    jobs += [(None, int(seeds[args.logs + i])) for i in range(args.logs)]
    hits = {(n, c is None): [] for n in blocks for c in (None, "x")}
    secs = {n: [] for n in blocks}
    for cause, s in jobs:
        for n, hit, sec in run_one(cause, s, args.duration, args.cutoff, blocks):
            hits[(n, cause is None)].append(hit)
            secs[n].append(sec)
    print("| blocks | named (hidden) | false alarms (clean) | s per log (median) |")
    print("|---|---|---|---|")
    for n in blocks:
        named, alarms = hits[(n, False)], hits[(n, True)]
        print(
            f"| {n} | {sum(named)}/{len(named)} = {np.mean(named):.0%} | "
            f"{sum(alarms)}/{len(alarms)} = {np.mean(alarms):.0%} | {np.median(secs[n]):.1f} |"
        )
    print(f"load average at the end: {os.getloadavg()[0]:.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
