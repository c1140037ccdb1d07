"""Are the detection limits `diagnose` prints true? (issue #31: name the cause or say it cannot)

On the engine's toy domain (tests/diagnose/toy.py: a linear baseline per channel, AR(1) noise), the
limit of a curve on channel c1 (the ``square`` candidate's ``detection_limits`` entry, taken on
``--clean`` clean logs, median) is the RMS of the smallest such effect found 80 % of the time. A
curve x² whose part the baseline cannot take up has RMS k × that limit is then hidden on
``--logs`` other logs for each k, and the bench prints how often a curve (``square`` or ``poly``)
is named on c1: about 0.8 at k = 1, near 1 above, near 0 well below.

    .venv/bin/python bench/bench_detection_limits.py --logs 40
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests" / "diagnose"))

from toy import ToyAdapter, make_data  # noqa: E402

from diegocal.diagnose.engine import EngineOptions, run_unit  # noqa: E402
from diegocal.evaluate import split_blocks  # noqa: E402


def diagnose(seed: int, effects=()):
    t, x, y = make_data(seed, effects=list(effects))
    return run_unit(ToyAdapter(t, x, y), split_blocks(len(t)), EngineOptions())


def curve_size(x: np.ndarray, rms: float) -> float:
    """The size of ``size · x²`` whose part the baseline (a x + b) cannot take up has RMS ``rms``."""
    A = np.column_stack([x, np.ones_like(x)])
    q = x**2 - A @ np.linalg.lstsq(A, x**2, rcond=None)[0]
    return rms / float(np.sqrt(np.mean(q**2)))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--logs", type=int, default=40, help="logs per multiple of the limit")
    ap.add_argument("--clean", type=int, default=9, help="clean logs the limit is taken on")
    ap.add_argument("--seed", type=int, default=1000)
    ap.add_argument("--multiples", default="0.5,0.75,1,1.5,2")
    args = ap.parse_args(argv)
    start = time.perf_counter()
    limits, by = [], []
    for seed in range(args.clean):
        d = diagnose(seed)
        entry = next(x for x in d.detection_limits if (x["cause"], x["channel"]) == ("square", "c1"))
        limits.append(entry["rms"])
        by.append(entry["by"])
    limit = float(np.median(limits))
    print(f"bench_detection_limits: toy domain, load {os.getloadavg()[0]:.1f}")
    print(f"limit of a curve on c1 over {args.clean} clean logs: median {limit:.4g} (range {min(limits):.4g}-"
          f"{max(limits):.4g}); set by {', '.join(f'{b} {by.count(b)}' for b in sorted(set(by)))}")
    print("| multiple of the limit | logs | curve named on c1 |")
    print("|---|---|---|")
    for k in (float(m) for m in args.multiples.split(",")):
        hits = 0
        for i in range(args.logs):
            seed = args.seed + i
            x = make_data(seed)[1]  # the states do not depend on the effects
            d = diagnose(seed, [("quadratic", "c1", curve_size(x[:, 1], k * limit))])
            hits += any(f.channel == "c1" and f.cause in ("square", "poly") for f in d.findings)
        print(f"| {k:g} | {args.logs} | {hits}/{args.logs} = {hits / args.logs:.2f} |")
    print(f"{time.perf_counter() - start:.0f} s wall, load average at the end {os.getloadavg()[0]:.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
