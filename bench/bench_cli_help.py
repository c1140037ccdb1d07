"""How long `diegocal --help` and `diegocal stac --help` take, against references measured in the
same run (issue #32: goal under 0.5 s for both).

Each command runs ``--runs`` times in a fresh interpreter (the installed console script, as a user
types it); the table shows the median, the spread and the load average when the runs started, beside
``python -c pass`` (the interpreter alone) and ``python -c 'import typer.main'`` (the parser every
command needs). Then, with ``--importtime``, the slowest imports of ``diegocal stac --help``
(``python -X importtime``, cumulative microseconds).

    .venv/bin/python bench/bench_cli_help.py [--runs 5] [--importtime]
"""

from __future__ import annotations

import argparse
import os
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


def wall(cmd: list[str], runs: int) -> list[float]:
    env = {**os.environ, "COLUMNS": "100"}
    out = []
    for _ in range(runs):
        t0 = time.perf_counter()
        subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env, check=True)
        out.append(time.perf_counter() - t0)
    return out


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
    print(f"{'command':<34}{'median s':>10}{'min s':>8}{'max s':>8}  load average (1 min) at start")
    for name, cmd in cases().items():
        load = os.getloadavg()[0]
        times = wall(cmd, args.runs)
        flag = "" if not name.startswith("diegocal") else ("  ok" if statistics.median(times) < GOAL_S else "  SLOW")
        print(f"{name:<34}{statistics.median(times):>10.3f}{min(times):>8.3f}{max(times):>8.3f}  {load:.2f}{flag}")
    print(f"(median of {args.runs} runs each; goal for the diegocal rows: under {GOAL_S} s)")
    if args.importtime:
        print("\nslowest imports of `diegocal stac --help` (cumulative µs; indented: imported by the one above)")
        for us, name in importtime(cases()["diegocal stac --help"]):
            print(f"{us:>10}  {name}")


if __name__ == "__main__":
    main()
