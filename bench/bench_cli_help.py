"""How long `diegocal --help` and `diegocal stac --help` take, against references measured in the
same run (issue #32: goal under 0.5 s for both).

Each command runs ``--runs`` times in a fresh interpreter (the installed console script, as a user
types it); the table shows the median wall time, its spread, the median CPU time (user + system of
the process: steadier than wall time on a shared machine) and the load average when the runs
started, beside ``python -c pass`` (the interpreter alone) and ``python -c 'import typer.main'``
(the parser every command needs). Then, with ``--importtime``, the slowest imports of
``diegocal stac --help`` (``python -X importtime``, cumulative microseconds).

    .venv/bin/python bench/bench_cli_help.py [--runs 5] [--importtime]
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

BIN = Path(sys.executable).parent
GOAL_S = 0.5


def cases() -> dict[str, list[str]]:
    script = BIN / "diegocal"
    cli = [str(script)] if script.exists() else [sys.executable, "-m", "diegocal"]
    return {
        "python -c pass": [sys.executable, "-c", "pass"],
        "python -c 'import typer.main'": [sys.executable, "-c", "import typer.main"],
        "diegocal --help": [*cli, "--help"],
        "diegocal stac --help": [*cli, "stac", "--help"],
        "diegocal batch --help": [*cli, "batch", "--help"],
    }


def timed(cmd: list[str], runs: int) -> tuple[list[float], list[float]]:
    """Wall and CPU (user + system) seconds of ``runs`` runs of ``cmd``."""
    env = {**os.environ, "COLUMNS": "100"}
    walls, cpus = [], []
    for _ in range(runs):
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env, check=True)
        walls.append(time.perf_counter() - t0)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpus.append(after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime)
    return walls, cpus


def importtime(cmd: list[str], top: int = 15) -> list[tuple[int, str]]:
    """The ``top`` slowest imports (cumulative µs) of ``cmd`` run under ``python -X importtime``."""
    args = cmd[1:] if cmd[0] == sys.executable else ["-m", "diegocal", *cmd[1:]]
    err = subprocess.run(
        [sys.executable, "-X", "importtime", *args], capture_output=True, text=True, check=False
    ).stderr
    rows = []
    for line in err.splitlines():
        parts = line.split("|")
        if line.startswith("import time:") and len(parts) == 3 and parts[1].strip().isdigit():
            rows.append((int(parts[1]), parts[2].rstrip()))
    return sorted(rows)[-top:]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--importtime", action="store_true", help="Also list the slowest imports of stac --help.")
    args = ap.parse_args()
    print(f"{'command':<32}{'median s':>9}{'min s':>7}{'max s':>7}{'CPU s':>7}  load average (1 min) at start")
    for name, cmd in cases().items():
        load = os.getloadavg()[0]
        walls, cpus = timed(cmd, args.runs)
        median = statistics.median(walls)
        flag = "" if not name.startswith("diegocal") else ("  ok" if median < GOAL_S else "  SLOW")
        print(
            f"{name:<32}{median:>9.3f}{min(walls):>7.3f}{max(walls):>7.3f}{statistics.median(cpus):>7.3f}"
            f"  {load:.2f}{flag}"
        )
    print(f"(median of {args.runs} runs each; goal for the diegocal rows: a median under {GOAL_S} s)")
    if args.importtime:
        print("\nslowest imports of `diegocal stac --help` (cumulative µs; indented: imported by the one above)")
        for us, name in importtime(cases()["diegocal stac --help"]):
            print(f"{us:>10}  {name}")


if __name__ == "__main__":
    main()
