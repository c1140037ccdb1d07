"""Does `diagnose --domain kinematics` say `unexplained` (or nothing) rather than a wrong name when
a sensor misbehaves in a way no cause of its vocabulary describes? (issue #31, item 1, kinematics)

Each log is a clean 30-s finger session of the project's simulator with one shape of
:mod:`experiments.kinematics_oov` added (a worn pot track, gear runout, a warming pot, crosstalk
between pots, a marker on a compliant stalk; U(4, 10) × the channel's noise). A log is
*misnamed* when any finding names a cause other than ``unexplained``, except that a pot's transfer
curve (``sensor_nonlinearity`` on the same pot) is an acceptable name for a worn track or runout
(:data:`ACCEPTABLE`); *unexplained* counts the logs with an ``unexplained`` finding on the affected
channel. Goal: ≥ 90 % not misnamed. The shapes are built from the simulator's ``/truth``; the
diagnosis never sees it.

    python bench/bench_diagnose_kinematics_oov.py --logs 6 --jobs 2
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from experiments.kinematics_oov import SHAPES, add_shape  # noqa: E402

ACCEPTABLE = {"worn_track": {"sensor_nonlinearity"}, "runout": {"sensor_nonlinearity"}}


def run_one(task) -> dict:
    """Diagnose one log with the defaults; the findings as (cause, channel)."""
    from diegocal.diagnose import DiagnoseOptions, diagnose

    shape, seed = task
    log, robot, channel, ratio = add_shape(shape, seed)
    start = time.perf_counter()
    result = diagnose(log, robot, DiagnoseOptions(domain="kinematics"))
    found = [(f.cause, f.channel) for f in result.findings]
    ok = ACCEPTABLE.get(shape, set())
    wrong = [(c, ch) for c, ch in found if c != "unexplained" and not (c in ok and ch == channel)]
    return {
        "shape": shape,
        "seed": seed,
        "channel": channel,
        "ratio": ratio,
        "findings": found,
        "misnamed": bool(wrong),
        "unexplained": ("unexplained", channel) in found,
        "named_ok": any(c in ok and ch == channel for c, ch in found),
        "seconds": time.perf_counter() - start,
    }


def table(rows, shapes=SHAPES, size: str = "size / noise") -> str:
    """Per shape: logs misnamed, `unexplained` on the channel, acceptable names, nothing; the sizes."""
    out = [
        f"| shape | logs | misnamed | `unexplained` on its channel | acceptable name | nothing | {size} |",
        "|---|---|---|---|---|---|---|",
    ]
    for shape in shapes:
        r = [x for x in rows if x["shape"] == shape]
        if not r:
            continue
        n = len(r)
        out.append(
            f"| {shape} | {n} | {sum(x['misnamed'] for x in r)}/{n} | {sum(x['unexplained'] for x in r)}/{n} | "
            f"{sum(x['named_ok'] for x in r)}/{n} | {sum(not x['findings'] for x in r)}/{n} | "
            f"{min(x['ratio'] for x in r):.3g} to {max(x['ratio'] for x in r):.3g} |"
        )
    n = len(rows)
    good = n - sum(x["misnamed"] for x in rows)
    out.append(f"| **all** | {n} | **{good / max(n, 1):.0%} not misnamed** (goal ≥ 90 %) | | | | |")
    return "\n".join(out)


def run(run_one, tasks, jobs: int, verbose: bool) -> list:
    """``run_one`` over ``tasks`` in ``jobs`` processes, a line per log with ``verbose``."""
    with ProcessPoolExecutor(jobs) as pool:
        rows = []
        for row in pool.map(run_one, tasks):
            rows.append(row)
            if verbose:
                print(
                    f"{row['shape']:11s} {row['channel']:11s} {row['ratio']:.3g} seed {row['seed']}: "
                    f"{row['findings'] or 'nothing'}{'  MISNAMED' if row['misnamed'] else ''}",
                    flush=True,
                )
    return rows


def bench_main(argv, doc: str, shapes, run_one, size: str) -> int:
    """An out-of-vocabulary bench's command line: ``--logs`` per shape of ``shapes``, each log
    judged by ``run_one((shape, seed))``; the table (:func:`table`, ``size``: its last column)."""
    parser = argparse.ArgumentParser(description=doc.splitlines()[0])
    parser.add_argument("--logs", type=int, default=6, help="logs per shape")
    parser.add_argument("--seed", type=int, default=None, help="first seed (default: fresh, printed)")
    parser.add_argument("--shape", action="append", choices=shapes, help="default: all")
    parser.add_argument("--jobs", type=int, default=1)
    parser.add_argument("--verbose", action="store_true", help="one line per log")
    args = parser.parse_args(argv)
    seed = args.seed if args.seed is not None else int(np.random.SeedSequence().entropy % 2**31)
    print(f"seed {seed}; load {os.getloadavg()[0]:.1f}", flush=True)
    chosen = args.shape or shapes
    tasks = [(shape, seed + 1000 * k + n) for k, shape in enumerate(chosen) for n in range(args.logs)]
    start = time.perf_counter()
    rows = run(run_one, tasks, args.jobs, args.verbose)
    print(table(rows, chosen, size))
    print(f"{time.perf_counter() - start:.0f} s wall, median {np.median([r['seconds'] for r in rows]):.1f} s per log; "
          f"load {os.getloadavg()[0]:.1f}")
    return 0


def main(argv=None) -> int:
    return bench_main(argv, __doc__, SHAPES, run_one, "size / noise")


if __name__ == "__main__":
    raise SystemExit(main())
